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
# the four corners centre + su * half_u + sv * half_v, (su, sv) in (1, 1), (1, -1), (-1, 1), (-1, -1)
_SIGN_U = np.array([1.0, 1.0, -1.0, -1.0])[None, :, None]
_SIGN_V = np.array([1.0, -1.0, 1.0, -1.0])[None, :, None]
_UNBOUNDED_BOX = np.array([-UNBOUNDED_PX, -UNBOUNDED_PX, UNBOUNDED_PX, UNBOUNDED_PX])


def screen_bounds_px(centres_rel_m: np.ndarray, half_u_m: np.ndarray, half_v_m: np.ndarray,
                     pixel_to_ray: np.ndarray, width_px: int, height_px: int) -> np.ndarray:
    """(n, 4) boxes ``(x_min, y_min, x_max, y_max)`` in pixels (x right, y down).

    ``centres_rel_m`` are the primitives' centres relative to the centre of projection; the ray
    of pixel (x, y) is ``pixel_to_ray @ (x / width, y / height, 1)``. Runs every frame for each eye,
    so it is written in few numpy calls (a box that is not finite, NaN included, fails ``|box| < 1e30``).

    Examples
    --------
    >>> from psyop.optics import VIVE_PRO, make_eye_camera
    >>> cam = make_eye_camera(VIVE_PRO, "right", (0.0, 0.0, -1.0), 0.064, 0.0076916, "conventional")
    >>> box = screen_bounds_px(np.array([[0.0, 0.0, -1.0]]), np.array([[0.1, 0.0, 0.0]]),
    ...                        np.array([[0.0, 0.1, 0.0]]), cam.pixel_to_ray, 1440, 1600)[0]
    >>> bool(box[0] < box[2] and box[1] < box[3])
    True
    """
    c = np.asarray(centres_rel_m, dtype=np.float64).reshape(-1, 3)
    hu = np.asarray(half_u_m, dtype=np.float64).reshape(-1, 3)
    hv = np.asarray(half_v_m, dtype=np.float64).reshape(-1, 3)
    corners = c[:, None, :] + _SIGN_U * hu[:, None, :] + _SIGN_V * hv[:, None, :]
    inv = np.linalg.inv(np.asarray(pixel_to_ray, dtype=np.float64))
    uvw = corners @ inv.T  # (n, 4, 3); w > 0 in front of the centre of projection
    w = uvw[..., 2]
    in_front = (w > 1e-12 * np.sqrt(np.add.reduce(corners * corners, axis=-1))).all(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        xy = uvw[..., :2] / w[..., None] * (width_px, height_px)  # (n, 4, 2) corners in pixels
    boxes = np.concatenate([xy.min(axis=1), xy.max(axis=1)], axis=1)
    finite = in_front & (np.abs(boxes) < UNBOUNDED_PX).all(axis=1)
    boxes[~finite] = _UNBOUNDED_BOX
    return boxes
