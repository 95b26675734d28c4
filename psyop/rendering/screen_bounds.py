"""Conservative screen-space bounds of the primitives, per frame on the CPU (float64).

Every primitive (disc or parallelogram, optionally clipped by a border) lies inside the
parallelogram ``centre +- half_u +- half_v``. A perspective map sends a planar convex polygon
lying wholly in front of the centre of projection to the convex polygon of its projected
corners, so the box around the four projected corners contains every pixel the primitive can
cover. A primitive with a corner at or behind the centre of projection gets an unbounded box.
The adaptive edge pass uses these boxes only to skip primitives that cannot reach a pixel, so a
loose box costs time, never accuracy.
"""

from __future__ import annotations

import numpy as np

UNBOUNDED_PX = 1.0e30


def screen_bounds_px(centres_rel_m: np.ndarray, half_u_m: np.ndarray, half_v_m: np.ndarray,
                     pixel_to_ray: np.ndarray, width_px: int, height_px: int) -> np.ndarray:
    """(n, 4) boxes ``(x_min, y_min, x_max, y_max)`` in pixels (x right, y down).

    ``centres_rel_m`` are the primitives' centres relative to the centre of projection; the ray
    of pixel (x, y) is ``pixel_to_ray @ (x / width, y / height, 1)``.
    """
    c = np.asarray(centres_rel_m, dtype=np.float64).reshape(-1, 3)
    hu = np.asarray(half_u_m, dtype=np.float64).reshape(-1, 3)
    hv = np.asarray(half_v_m, dtype=np.float64).reshape(-1, 3)
    signs = np.array([[1.0, 1.0], [1.0, -1.0], [-1.0, 1.0], [-1.0, -1.0]])
    corners = c[:, None, :] + signs[None, :, :1] * hu[:, None, :] + signs[None, :, 1:] * hv[:, None, :]
    inv = np.linalg.inv(np.asarray(pixel_to_ray, dtype=np.float64))
    uvw = corners @ inv.T  # (n, 4, 3); w > 0 in front of the centre of projection
    w = uvw[..., 2]
    in_front = np.all(w > 1e-12 * np.linalg.norm(corners, axis=-1), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = uvw[..., 0] / w * width_px
        y = uvw[..., 1] / w * height_px
    boxes = np.stack([x.min(axis=1), y.min(axis=1), x.max(axis=1), y.max(axis=1)], axis=-1)
    finite = in_front & np.all(np.isfinite(boxes), axis=1) & np.all(np.abs(boxes) < UNBOUNDED_PX, axis=1)
    boxes[~finite] = (-UNBOUNDED_PX, -UNBOUNDED_PX, UNBOUNDED_PX, UNBOUNDED_PX)
    return boxes
