"""Mesh silhouettes in audited frames against exact ray-triangle intersection.

For each mesh item of a frame's scene the rasterised silhouette is measured like a primitive's
visible area (:mod:`psyop.audit.masks`): the scene is rendered again, with the session's renderer
and camera, with that mesh in marker red (unlit, no texture or vertex colour) and every other
mesh, every primitive, the background and the aperture's surround black. Occlusion is resolved
as in the participant's frame (one depth for the mesh pass and the ray-cast), so the red sum is
the mesh's visible coverage per pixel, edges included to the mesh pass's anti-aliasing (MSAA 4x, what llvmpipe
gives: docs/rendering.md, "Meshes").

The reference is :func:`psyop.rendering.mesh_exact.exact_coverage` on the same camera: float64
rays through :data:`EXACT_SAMPLES_PER_AXIS` ^ 2 points per pixel, Moeller-Trumbore against every
triangle and the planar primitives, the nearest hit per ray wins (no rasteriser, no GPU). A mesh
narrower than :data:`MIN_MSAA_PX_ACROSS` pixels is measured in both paths in the same magnified
window (:func:`psyop.audit.masks.zoom_window`), occluders included. Two numbers are checked: the
visible areas (within :data:`MESH_AREA_RELATIVE_TOLERANCE` + :data:`MESH_AREA_FLOOR_WINDOW_PX`) and
the silhouettes' mismatch, the sum of per-pixel coverage differences (within
:data:`EDGE_PIXEL_TOLERANCE` per exact edge pixel), which a moved or wrongly occluded silhouette of
the right area exceeds.

BLEND parts write no depth, so they hide nothing and are left out of both paths (the silhouette
is the opaque parts'). Not compared (a note says so, never a silent pass): a frame with a mesh
whose MASK part takes its alpha from a texture or vertex colours (the exact path does not sample
alpha), with an aperture, or with a primitive with a sinusoidal border (the exact path models
neither).
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass

import numpy as np

from psyop.mesh.asset import AlphaMode, MeshAsset, MeshPart
from psyop.optics.camera import EyeCamera
from psyop.rendering import Renderer
from psyop.rendering.camera_math import project_points_px
from psyop.rendering.mesh_exact import exact_coverage
from psyop.rendering.mesh_scene import MeshInstance
from psyop.rendering.scene import Scene
from psyop.rendering.screen_bounds import UNBOUNDED_PX

#: Exact sample rays per pixel axis (4 x 4 per pixel of the measuring window, as the mesh-pass tests use).
EXACT_SAMPLES_PER_AXIS = 4
#: The mesh pass's anti-aliasing (RenderSettings.msaa_samples; llvmpipe gives 4).
MSAA_SAMPLES = 4
#: MSAA 4x samples about 2 points per pixel axis; a mesh's window is magnified until its screen box spans
#: :data:`psyop.audit.masks.MIN_SAMPLES_ACROSS` of them (128 pixels), at most 16-fold, within 128 x 128 pixels.
MSAA_SAMPLES_PER_AXIS = 2
#: Allowed disagreement between the rendered and the exact visible area: 2 % of the exact area (the
#: mesh-pass tests' mixed-scene bound, MSAA 4x against 16 exact samples per pixel) ...
MESH_AREA_RELATIVE_TOLERANCE = 0.02
#: ... plus this many pixels of the measuring window (a silhouette a few pixels across, or none, is
#: then held to a few pixels' worth of edge samples rather than to a percentage of nothing).
MESH_AREA_FLOOR_WINDOW_PX = 2.0

#: Allowed silhouette mismatch per edge pixel of the exact map (0 < coverage < 1): MSAA 4x and 4 x 4 exact
#: rays may disagree there by up to half a pixel (tests/rendering/test_mesh_pass.py), nowhere else; a
#: silhouette moved by a pixel or more, or drawn in the wrong occlusion order, exceeds it.
EDGE_PIXEL_TOLERANCE = 0.5

RED = (1.0, 0.0, 0.0, 1.0)
BLACK = (0.0, 0.0, 0.0, 1.0)


@dataclass(frozen=True)
class MeshCheck:
    """One mesh item in one frame: rendered and exact visible area in pixels of the audited frame
    (``psyop audit`` scales them to display pixels), the allowed disagreement in the same unit, and why it
    was not compared (``skipped``: empty when it was)."""

    name: str
    rendered_px2: float
    exact_px2: float
    tolerance_px2: float
    magnification: int = 1
    skipped: str = ""
    #: sum over pixels of |rendered - exact| coverage (a moved silhouette of equal area shows here) and its bound
    mismatch_px2: float = 0.0
    mismatch_tolerance_px2: float = 0.0

    @property
    def error_px2(self) -> float:
        return abs(self.rendered_px2 - self.exact_px2)

    @property
    def relative_error(self) -> float:
        """Disagreement as a fraction of the exact area (0 when both are 0, inf when only the render has area)."""
        if self.exact_px2 > 0:
            return self.error_px2 / self.exact_px2
        return 0.0 if self.error_px2 == 0 else float("inf")

    @property
    def passed(self) -> bool:
        return bool(self.skipped) or (self.error_px2 <= self.tolerance_px2
                                      and self.mismatch_px2 <= self.mismatch_tolerance_px2)


def silhouette_parts(asset: MeshAsset) -> tuple[MeshPart, ...]:
    """The parts that make a mesh's silhouette and hide what is behind it: OPAQUE parts, and MASK parts whose
    alpha is one constant (no texture, no vertex colours) at or above the cutoff. BLEND parts write no depth
    (docs/rendering.md, "Meshes"): they tint what is behind them and hide nothing, so they are left out of
    both paths."""
    out = []
    for p in asset.parts:
        if p.alpha_mode is AlphaMode.OPAQUE:
            out.append(p)
        elif p.alpha_mode is AlphaMode.MASK and p.texture is None and p.colours is None:
            if p.base_colour[3] >= p.alpha_cutoff:
                out.append(p)
    return tuple(out)


def unmodelled(asset: MeshAsset) -> str:
    """Why the exact path cannot give this asset's silhouette ('' when it can): a MASK part whose alpha
    varies (a texture's or vertex colours' alpha)."""
    for p in asset.parts:
        if p.alpha_mode is AlphaMode.MASK and (p.texture is not None or p.colours is not None):
            return (f"its part on node {p.node} (mesh {p.mesh_index}, primitive {p.primitive_index}) is alpha MASK "
                    "with a texture or vertex colours (the exact path does not sample alpha)")
    return ""


class MarkerAssets:
    """Mesh assets repainted in one colour (unlit: base colour only) with only their :func:`silhouette_parts`,
    made once per (asset, colour) so the mesh pass uploads each once (it keys its buffers by the asset
    object)."""

    def __init__(self) -> None:
        self._made: dict[tuple[int, tuple[float, ...]], tuple[MeshAsset, MeshAsset]] = {}

    def painted(self, asset: MeshAsset, colour: tuple[float, float, float, float]) -> MeshAsset:
        key = (id(asset), tuple(colour))
        entry = self._made.get(key)
        if entry is None or entry[0] is not asset:
            parts = tuple(dataclasses.replace(p, base_colour=colour, texture=None, colours=None,
                                              alpha_mode=AlphaMode.OPAQUE) for p in silhouette_parts(asset))
            entry = (asset, dataclasses.replace(asset, parts=parts))
            self._made[key] = entry
        return entry[1]

    def instance(self, inst: MeshInstance, colour: tuple[float, float, float, float]) -> MeshInstance:
        """``inst`` drawn in ``colour``, unlit, with the same placement and name."""
        return MeshInstance(self.painted(inst.asset, colour), inst.model_m, inst.name)


def mesh_mask_scene(mask: Scene, scene: Scene, index: int, markers: MarkerAssets) -> Scene:
    """``mask`` (a black-primitive mask scene of ``scene``) with mesh ``index`` red and every other mesh black
    (each with its :func:`silhouette_parts` only)."""
    meshes = tuple(markers.instance(m, RED if i == index else BLACK) for i, m in enumerate(scene.meshes)
                   if silhouette_parts(m.asset))
    return dataclasses.replace(mask, meshes=meshes)


def silhouette_scene(scene: Scene, markers: MarkerAssets) -> Scene:
    """``scene`` with every mesh reduced to its :func:`silhouette_parts` (the exact path's input)."""
    meshes = tuple(markers.instance(m, BLACK) for m in scene.meshes if silhouette_parts(m.asset))
    return dataclasses.replace(scene, meshes=meshes)


def mesh_screen_box_px(inst: MeshInstance, camera: EyeCamera) -> np.ndarray:
    """(4,) box (x_min, y_min, x_max, y_max) of the placed bounding box's corners in ``camera``'s pixels;
    unbounded when a corner lies behind the centre of projection."""
    lo, hi = np.asarray(inst.asset.bbox_min, float), np.asarray(inst.asset.bbox_max, float)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    model = inst.model
    xy = project_points_px(camera, corners @ model[:3, :3].T + model[:3, 3])
    if not np.isfinite(xy).all():
        return np.array([-UNBOUNDED_PX, -UNBOUNDED_PX, UNBOUNDED_PX, UNBOUNDED_PX])
    return np.array([xy[:, 0].min(), xy[:, 1].min(), xy[:, 0].max(), xy[:, 1].max()])


def not_compared(scene: Scene, inst: MeshInstance) -> str:
    """Why the exact path cannot give this mesh's reference silhouette in this scene ('' when it can)."""
    for m in scene.meshes:
        why = unmodelled(m.asset)
        if why:
            return f"mesh {m.name}: {why}" if m.name != inst.name else why
    if not silhouette_parts(inst.asset):
        return "it has only BLEND parts (they hide nothing; no silhouette to compare)"
    if scene.aperture is not None:
        return "the frame has an aperture (the exact path does not model it)"
    bordered = [p.name for p in scene.primitives if p.border is not None]
    if bordered:
        return f"primitive {bordered[0]} has a sinusoidal border (the exact path does not model it)"
    return ""


def measure_window(renderer: Renderer, mask: Scene, exact_scene: Scene, name: str, camera: EyeCamera,
                   eye: str) -> tuple[np.ndarray, np.ndarray]:
    """(rendered, exact) (h, w) coverage of mesh ``name``'s visible part per pixel of ``camera`` (a frame or a
    magnified window): the red channel of ``mask`` rendered, and the exact coverage of ``exact_scene``'s item
    of that name (zeros when it has none)."""
    renderer.set_scene(mask)
    renderer.render(camera)
    rendered = renderer.image(eye)[..., 0].astype(np.float64)
    with warnings.catch_warnings():  # triangles wholly behind the centre of projection: handled, not news
        warnings.filterwarnings("ignore", "All-NaN slice encountered", RuntimeWarning)
        cover = exact_coverage(camera, exact_scene, samples_per_axis=EXACT_SAMPLES_PER_AXIS).get(name)
    return rendered, np.zeros_like(rendered) if cover is None else np.asarray(cover, dtype=np.float64)


def compare(name: str, rendered: np.ndarray, exact: np.ndarray, magnification: int) -> MeshCheck:
    """The check of one mesh from its rendered and exact coverage maps in a window magnified ``magnification``
    times: areas, their allowed difference, and the silhouette mismatch (sum of per-pixel coverage
    differences) with its allowed :data:`EDGE_PIXEL_TOLERANCE` per exact edge pixel; in frame pixels."""
    scale = float(magnification * magnification)
    area = float(exact.sum())
    edges = int(np.count_nonzero((exact > 0) & (exact < 1)))
    return MeshCheck(name, float(rendered.sum()) / scale, area / scale,
                     (MESH_AREA_RELATIVE_TOLERANCE * area + MESH_AREA_FLOOR_WINDOW_PX) / scale, magnification,
                     mismatch_px2=float(np.abs(rendered - exact).sum()) / scale,
                     mismatch_tolerance_px2=(EDGE_PIXEL_TOLERANCE * edges + MESH_AREA_FLOOR_WINDOW_PX) / scale)
