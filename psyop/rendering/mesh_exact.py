"""Exact ray casting of meshes and primitives in numpy, independent of the rasteriser.

The reference the mesh pass is measured against (tests, ``psyop audit``): rays from the camera's centre
of projection through pixel sample points (``EyeCamera.pixel_to_ray``, float64), intersected with every
triangle (Moeller-Trumbore) and with the scene's planar primitives; the nearest hit per ray names the item
it shows. No projection matrix, no GPU. Triangles are binned into screen tiles by their projected
bounding boxes, so a ray meets only the triangles that can reach its tile.
"""

from __future__ import annotations

from psyop.optics.camera import EyeCamera

import numpy as np

from psyop.rendering.camera_math import project_points_px
from psyop.rendering.mesh_scene import MeshInstance
from psyop.rendering.scene import Primitive, Scene, Shape

TILE_PX = 16


def triangles_head_m(instance: MeshInstance) -> np.ndarray:
    """(m, 3, 3) float64 triangle corners of a placed mesh in head space."""
    model = instance.model
    out = []
    for part in instance.asset.parts:
        pts = np.asarray(part.positions, dtype=np.float64) @ model[:3, :3].T + model[:3, 3]
        out.append(pts[np.asarray(part.indices, dtype=np.int64)])
    return np.concatenate(out) if out else np.zeros((0, 3, 3))


def ray_triangles(origin: np.ndarray, dirs: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(n,) distance along each unit ray ``dirs`` from ``origin`` to the nearest of ``tris`` (inf: none);
    both faces count (the audit measures what can be seen, single-sided culling aside)."""
    best = np.full(len(dirs), np.inf)
    if len(tris) == 0 or len(dirs) == 0:
        return best
    chunk = max(1, 2_000_000 // max(1, len(dirs)))
    for start in range(0, len(tris), chunk):
        t = tris[start:start + chunk]
        e1 = t[:, 1] - t[:, 0]
        e2 = t[:, 2] - t[:, 0]
        p = np.cross(dirs[:, None, :], e2[None, :, :])  # (n, k, 3)
        det = np.einsum("nkc,kc->nk", p, e1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = origin[None, None, :] - t[None, :, 0, :]
            u = np.einsum("nkc,nkc->nk", s, p) * inv
            q = np.cross(s, e1[None, :, :])
            v = np.einsum("nc,nkc->nk", dirs, q) * inv
            dist = np.einsum("kc,nkc->nk", e2, q) * inv
        hit = (np.abs(det) > 1e-300) & (u >= 0) & (v >= 0) & (u + v <= 1) & (dist > 0)
        best = np.minimum(best, np.where(hit, dist, np.inf).min(axis=1))
    return best


def ray_primitive(origin: np.ndarray, dirs: np.ndarray, prim: Primitive) -> np.ndarray:
    """(n,) distance along unit rays to a planar primitive (inf: missed; a primitive at optical infinity
    is hit at inf and never occludes). Sinusoidal borders are not modelled (ValueError)."""
    if prim.border is not None:
        raise ValueError(f"primitive {prim.name!r}: the exact mesh path does not model sinusoidal borders")
    c, u, v = (np.asarray(x, dtype=np.float64) for x in (prim.centre_m, prim.half_u_m, prim.half_v_m))
    if prim.at_infinity:
        return np.full(len(dirs), np.inf)
    n = np.cross(u, v)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((c - origin) @ n) / (dirs @ n)
    x = origin + t[:, None] * dirs - c
    a = x @ u / (u @ u)
    b = x @ v / (v @ v)
    inside = (a * a + b * b <= 1.0) if prim.shape is Shape.DISC else ((np.abs(a) <= 1) & (np.abs(b) <= 1))
    return np.where(inside & (t > 0), t, np.inf)


def sample_rays(camera: EyeCamera, x0_px: int, y0_px: int, width_px: int, height_px: int,
                samples_per_axis: int) -> np.ndarray:
    """(height, width, s*s, 3) unit head-space rays through an s x s grid in each pixel of the window."""
    s = int(samples_per_axis)
    offs = (np.arange(s) + 0.5) / s
    ys = y0_px + np.arange(height_px)[:, None] + offs[None, :]  # (h, s)
    xs = x0_px + np.arange(width_px)[:, None] + offs[None, :]
    px = np.broadcast_to(xs[None, :, None, :], (height_px, width_px, s, s))
    py = np.broadcast_to(ys[:, None, :, None], (height_px, width_px, s, s))
    uv1 = np.stack([px / camera.width_px, py / camera.height_px, np.ones_like(px)], axis=-1).reshape(
        height_px, width_px, s * s, 3)
    d = uv1 @ np.asarray(camera.pixel_to_ray, dtype=np.float64).T
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def _tiled_mesh_distance(camera: EyeCamera, origin: np.ndarray, rays: np.ndarray, x0: int, y0: int,
                         tris: np.ndarray) -> np.ndarray:
    """Nearest distance to ``tris`` for every ray of the window, testing per screen tile only the triangles
    whose projected box reaches it (a triangle with a corner behind the centre of projection reaches all)."""
    h, w, k, _ = rays.shape
    out = np.full((h, w, k), np.inf)
    if len(tris) == 0:
        return out
    xy = project_points_px(camera, tris.reshape(-1, 3)).reshape(-1, 3, 2)
    everywhere = ~np.isfinite(xy).all(axis=(1, 2))
    lo = np.where(everywhere[:, None], -np.inf, np.nanmin(np.where(np.isfinite(xy), xy, np.nan), axis=1))
    hi = np.where(everywhere[:, None], np.inf, np.nanmax(np.where(np.isfinite(xy), xy, np.nan), axis=1))
    for ty in range(0, h, TILE_PX):
        for tx in range(0, w, TILE_PX):
            bx0, by0 = x0 + tx - 1, y0 + ty - 1
            bx1, by1 = x0 + min(w, tx + TILE_PX) + 1, y0 + min(h, ty + TILE_PX) + 1
            sel = (lo[:, 0] <= bx1) & (hi[:, 0] >= bx0) & (lo[:, 1] <= by1) & (hi[:, 1] >= by0)
            if not sel.any():
                continue
            block = rays[ty:ty + TILE_PX, tx:tx + TILE_PX]
            dist = ray_triangles(origin, block.reshape(-1, 3), tris[sel])
            out[ty:ty + TILE_PX, tx:tx + TILE_PX] = dist.reshape(block.shape[:3])
    return out


def exact_coverage(camera: EyeCamera, scene: Scene, x0_px: int = 0, y0_px: int = 0, width_px: int | None = None,
                   height_px: int | None = None, samples_per_axis: int = 4) -> dict[str, np.ndarray]:
    """Per item name (mesh instances' and primitives' ``name``), the (h, w) fraction of each pixel's sample
    rays whose nearest hit is that item: exact silhouettes with occlusion between meshes and primitives."""
    w = camera.width_px - x0_px if width_px is None else int(width_px)
    h = camera.height_px - y0_px if height_px is None else int(height_px)
    origin = np.asarray(camera.centre_of_projection_m, dtype=np.float64)
    rays = sample_rays(camera, x0_px, y0_px, w, h, samples_per_axis)
    names: list[str] = []
    dists: list[np.ndarray] = []
    for inst in scene.meshes:
        names.append(inst.name)
        dists.append(_tiled_mesh_distance(camera, origin, rays, x0_px, y0_px, triangles_head_m(inst)))
    for prim in scene.primitives:
        names.append(prim.name)
        d = ray_primitive(origin, rays.reshape(-1, 3), prim).reshape(h, w, -1)
        if prim.at_infinity:
            hit = ray_primitive(np.zeros(3), rays.reshape(-1, 3), _unit_distance(prim)).reshape(h, w, -1)
            d = np.where(np.isfinite(hit), 1e300, np.inf)  # behind every finite surface
        dists.append(d)
    if not dists:
        return {}
    stack = np.stack(dists)  # (items, h, w, k)
    # nearest wins; a later-listed primitive wins at equal distance (the renderer's coplanar rule)
    nearest = np.min(stack, axis=0)
    winner = len(stack) - 1 - np.argmax(stack[::-1] <= nearest[None] * (1 + 1e-9), axis=0)
    winner = np.where(np.isfinite(nearest), winner, -1)
    out: dict[str, np.ndarray] = {}
    for index, name in enumerate(names):
        cov = (winner == index).mean(axis=-1)
        out[name] = out[name] + cov if name in out else cov
    return out


def _unit_distance(prim: Primitive) -> Primitive:
    """A primitive at optical infinity as the finite one at unit distance whose directions it stands for."""
    import dataclasses

    return dataclasses.replace(prim, at_infinity=False)
