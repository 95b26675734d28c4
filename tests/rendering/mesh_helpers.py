"""MeshAssets built straight from numpy arrays (no file, no loader) for the mesh-pass tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from psyop.mesh.asset import AlphaMode, Filter, MeshAsset, MeshPart, MeshTexture, Wrap


def part(positions, indices, *, colour=(1.0, 1.0, 1.0, 1.0), texcoords=None, texture=None, colours=None,
         node="n", alpha_mode=AlphaMode.OPAQUE, cutoff=0.5, double_sided=True) -> MeshPart:
    pos = np.asarray(positions, dtype=np.float64)
    return MeshPart(node=node, mesh_index=0, primitive_index=0, positions=pos,
                    indices=np.asarray(indices, dtype=np.uint32).reshape(-1, 3), normals=None,
                    texcoords=None if texcoords is None else np.asarray(texcoords, dtype=np.float32),
                    colours=None if colours is None else np.asarray(colours, dtype=np.float32),
                    base_colour=tuple(colour), texture=texture, alpha_mode=alpha_mode, alpha_cutoff=cutoff,
                    double_sided=double_sided, bbox_min=pos.min(axis=0), bbox_max=pos.max(axis=0))


def asset(*parts: MeshPart, name: str = "test.glb") -> MeshAsset:
    lo = np.min([p.bbox_min for p in parts], axis=0)
    hi = np.max([p.bbox_max for p in parts], axis=0)
    return MeshAsset(path=Path(name), sha256="0" * 64, node=None, parts=tuple(parts), bbox_min=lo, bbox_max=hi)


def quad_part(half_w: float, half_h: float, **kw) -> MeshPart:
    """A rectangle in the model's z = 0 plane, centred at the origin, facing +z, uv (0, 0) top-left."""
    pos = [(-half_w, -half_h, 0.0), (half_w, -half_h, 0.0), (half_w, half_h, 0.0), (-half_w, half_h, 0.0)]
    uv = [(0.0, 1.0), (1.0, 1.0), (1.0, 0.0), (0.0, 0.0)]
    return part(pos, [(0, 1, 2), (0, 2, 3)], texcoords=uv, **kw)


def disc_part(radius: float, segments: int = 256, **kw) -> MeshPart:
    """A disc in the model's z = 0 plane (a fan of ``segments`` triangles)."""
    a = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    pos = np.concatenate([[(0.0, 0.0, 0.0)], np.stack([radius * np.cos(a), radius * np.sin(a), 0 * a], axis=-1)])
    idx = [(0, 1 + i, 1 + (i + 1) % segments) for i in range(segments)]
    return part(pos, idx, **kw)


def checker_texture(n: int = 4, key: str = "checker") -> MeshTexture:
    """An n x n texture whose texel (row r, column c) has red = (c + 0.5) / n, green = (r + 0.5) / n."""
    img = np.zeros((n, n, 4), dtype=np.float32)
    img[..., 0] = ((np.arange(n) + 0.5) / n)[None, :]
    img[..., 1] = ((np.arange(n) + 0.5) / n)[:, None]
    img[..., 3] = 1.0
    return MeshTexture(key=key, rgba_linear=img, wrap_s=Wrap.CLAMP, wrap_t=Wrap.CLAMP, mag_filter=Filter.NEAREST,
                       min_filter=Filter.NEAREST)
