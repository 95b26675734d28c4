"""A mesh asset's draw data, prepared once per session and apart from any GL call.

The parts of a :class:`psyop.mesh.MeshAsset` are merged into *batches*: parts with the same texture,
alpha mode, cutoff, sidedness and normals share one interleaved vertex array and one index array, with
each part's base colour baked into its vertices' colours (linear base colour x COLOR_0). A frame then
issues one draw per batch (or per run of visible parts when some are culled), not one per glTF node,
so the CPU cost of a frame does not grow with the node count. BLEND batches come after the opaque and
mask ones, in the asset's part order (docs/rendering.md, "Meshes").

Positions are stored relative to the asset's bounding-box centre (``origin_m``, float64) before they
become float32, so a model authored far from its origin keeps its precision; the rasteriser folds the
origin back into the model matrix in float64.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from psyop.mesh.asset import AlphaMode, MeshAsset, MeshPart, MeshTexture

#: Floats per vertex: position (3), normal (3), texture coordinate (2), colour (4).
VERTEX_FLOATS = 12


@dataclass(frozen=True, eq=False)
class MeshBatch:
    """Parts drawn with one material state: ``vertices`` (n, 12) float32, ``indices`` (3 m,) uint32,
    ``part_first``/``part_count`` (k,) each part's range in ``indices``, ``part_index`` (k,) the part's
    index in the asset (its bounding box for culling)."""

    vertices: np.ndarray
    indices: np.ndarray
    part_first: np.ndarray
    part_count: np.ndarray
    part_index: np.ndarray
    texture: MeshTexture | None
    alpha_mode: AlphaMode
    alpha_cutoff: float
    double_sided: bool
    has_normals: bool


@dataclass(frozen=True, eq=False)
class PreparedMesh:
    """An asset's batches, its origin (float64, model units) and each part's bounding-box corners
    relative to that origin, homogeneous: (n parts, 8, 4) float64, for the per-frame frustum test."""

    batches: tuple[MeshBatch, ...]
    origin_m: np.ndarray
    part_corners: np.ndarray
    triangle_count: int


def _key(part: MeshPart) -> tuple[object, ...]:
    tex = None if part.texture is None else part.texture.key
    cutoff = float(part.alpha_cutoff) if part.alpha_mode is AlphaMode.MASK else 0.0
    return (tex, AlphaMode(part.alpha_mode).value, cutoff, bool(part.double_sided), part.normals is not None)


def _part_vertices(part: MeshPart, origin: np.ndarray) -> np.ndarray:
    n = part.positions.shape[0]
    out = np.zeros((n, VERTEX_FLOATS), dtype=np.float32)
    out[:, 0:3] = np.asarray(part.positions, dtype=np.float64) - origin
    if part.normals is not None:
        out[:, 3:6] = part.normals
    if part.texcoords is not None:
        out[:, 6:8] = part.texcoords
    colour = np.asarray(part.base_colour, dtype=np.float32).reshape(1, 4)
    out[:, 8:12] = colour if part.colours is None else np.asarray(part.colours, dtype=np.float32) * colour
    return out


def box_corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(8, 4) homogeneous corners of the box [lo, hi]."""
    return np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def prepare_mesh(asset: MeshAsset) -> PreparedMesh:
    """The batches and culling boxes of ``asset`` (numpy only; called once per asset and session)."""
    origin = (np.asarray(asset.bbox_min, dtype=np.float64) + np.asarray(asset.bbox_max, dtype=np.float64)) / 2.0
    groups: dict[tuple[object, ...], list[int]] = {}
    order: list[tuple[object, ...]] = []
    for index, part in enumerate(asset.parts):
        key = _key(part)
        if key not in groups:
            groups[key] = []
            order.append(key)
        groups[key].append(index)
    # opaque and mask batches first, then BLEND ones, each in the order of their first part
    order.sort(key=lambda k: k[1] == AlphaMode.BLEND.value)
    batches = []
    for key in order:
        vertices, indices, first, count = [], [], [], []
        base = 0
        offset = 0
        for index in groups[key]:
            part = asset.parts[index]
            vertices.append(_part_vertices(part, origin))
            flat = np.asarray(part.indices, dtype=np.uint32).reshape(-1) + np.uint32(base)
            indices.append(flat)
            first.append(offset)
            count.append(flat.size)
            offset += flat.size
            base += part.positions.shape[0]
        head = asset.parts[groups[key][0]]
        batches.append(MeshBatch(np.ascontiguousarray(np.concatenate(vertices)), np.concatenate(indices),
                                 np.array(first, dtype=np.int64), np.array(count, dtype=np.int64),
                                 np.array(groups[key], dtype=np.int64), head.texture, AlphaMode(head.alpha_mode),
                                 float(head.alpha_cutoff), bool(head.double_sided), head.normals is not None))
    corners = np.array([box_corners(np.asarray(p.bbox_min, dtype=np.float64) - origin,
                                    np.asarray(p.bbox_max, dtype=np.float64) - origin) for p in asset.parts])
    return PreparedMesh(tuple(batches), origin, corners.reshape(len(asset.parts), 8, 4), asset.triangle_count)


def visible_parts(part_corners: np.ndarray, clip_from_model: np.ndarray) -> np.ndarray:
    """(n parts,) bool: whether a part's bounding box can reach the view frustum (conservative: a box is
    culled only when all 8 corners lie outside one clip plane), one numpy product for all parts and two
    reductions (the per-plane tests of x, y and z against w side by side)."""
    clip = part_corners @ clip_from_model.T  # (n, 8, 4)
    xyz, w = clip[..., :3], clip[..., 3:]
    outside = ((xyz > w).all(axis=1) | (xyz < -w).all(axis=1)).any(axis=1)
    return ~outside


def draw_ranges(batch: MeshBatch, seen: np.ndarray) -> list[tuple[int, int]]:
    """(first, count) index ranges of ``batch`` to draw, ``seen`` (the batch's parts,) whether each part is
    visible: one for the whole batch when all its parts are, else one per run of consecutive visible parts
    (a batch's parts are consecutive in its index array: a run is one range), found with numpy, not part by part."""
    if seen.all():
        return [(0, int(batch.indices.size))]
    if not seen.any():
        return []
    edges = np.diff(np.concatenate(([0], seen.astype(np.int8), [0])))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    first = batch.part_first[starts]
    count = batch.part_first[stops] + batch.part_count[stops] - first
    return list(zip(first.tolist(), count.tolist(), strict=True))
