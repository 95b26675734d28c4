"""Exact pixel coverage of a straight-edged primitive (float64, no GPU).

A planar parallelogram entirely in front of the centre of projection projects through the
display to a convex quadrilateral (straight edges stay straight under a central projection).
Its exact coverage of each pixel square is the area of quadrilateral n square, computed here by
clipping the quadrilateral to each pixel (Sutherland-Hodgman). Used to measure the error of the
anti-aliasing effort spent on straight background edges (benchmarks/bench_frame_path.py).
"""

from __future__ import annotations

from psyop.optics.camera import EyeCamera

import numpy as np

from psyop.rendering.camera_math import project_points_px
from psyop.rendering.scene import Primitive, Shape


def projected_corners_px(camera: EyeCamera, rect: Primitive) -> np.ndarray:
    """(4, 2) image corners (x right, y down) of a RECT primitive, in order around it."""
    if rect.shape is not Shape.RECT:
        raise ValueError("exact coverage is for RECT primitives (straight edges)")
    c, u, v = (np.asarray(x, dtype=np.float64) for x in (rect.centre_m, rect.half_u_m, rect.half_v_m))
    corners = project_points_px(camera, np.array([c - u - v, c + u - v, c + u + v, c - u + v]))
    if not np.isfinite(corners).all():
        raise ValueError("the primitive must lie entirely in front of the centre of projection")
    return corners


def _clip(poly: list[tuple[float, float]], axis: int, bound: float, keep_below: bool) -> list[tuple[float, float]]:
    out: list[tuple[float, float]] = []
    n = len(poly)
    for k in range(n):
        p, q = poly[k], poly[(k + 1) % n]
        p_in = (p[axis] <= bound) if keep_below else (p[axis] >= bound)
        q_in = (q[axis] <= bound) if keep_below else (q[axis] >= bound)
        if p_in:
            out.append(p)
        if p_in != q_in:
            t = (bound - p[axis]) / (q[axis] - p[axis])
            out.append((p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])))
    return out


def _area(poly: list[tuple[float, float]]) -> float:
    if len(poly) < 3:
        return 0.0
    x = np.array([p[0] for p in poly])
    y = np.array([p[1] for p in poly])
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def coverage_px(corners_px: np.ndarray, width_px: int, height_px: int) -> np.ndarray:
    """(H, W) exact fraction of each pixel covered by the convex polygon ``corners_px``."""
    cov = np.zeros((height_px, width_px))
    poly = [(float(x), float(y)) for x, y in corners_px]
    x0, y0 = np.floor(corners_px.min(axis=0)).astype(int)
    x1, y1 = np.ceil(corners_px.max(axis=0)).astype(int)
    for j in range(max(0, y0), min(height_px, y1)):
        row = _clip(_clip(poly, 1, float(j), False), 1, float(j + 1), True)
        if len(row) < 3:
            continue
        for i in range(max(0, x0), min(width_px, x1)):
            cov[j, i] = _area(_clip(_clip(row, 0, float(i), False), 0, float(i + 1), True))
    return cov


def projected_area_px(camera: EyeCamera, primitive: Primitive, boundary_points: int = 4096) -> float:
    """Exact image area (px^2) of a disc or rect wholly in front of the centre of projection and
    inside the image: the shoelace area of its projected outline (a rect's four corners; a disc's
    outline at ``boundary_points`` points, relative error ~ (2 pi / n)^2 / 6, 4e-7 at 4096). A
    primitive at optical infinity is projected as directions. Borders are not supported.

    Examples
    --------
    >>> import numpy as np
    >>> from psyop.optics.display import VIVE_PRO
    >>> from psyop.rendering.builders import frontoparallel_rect
    >>> from psyop.rendering.measure import right_eye_camera
    >>> from psyop.rendering.scene import Solid
    >>> cam = right_eye_camera(0.0, 0.0, "ocular")
    >>> rect = frontoparallel_rect(1.0, 2.0, 2.0, Solid((1, 1, 1)))
    >>> bool(300 < projected_area_px(cam, rect) < 800)
    True
    """
    from psyop.rendering.camera_math import project_directions_px

    if primitive.border is not None:
        raise ValueError("projected_area_px does not take bordered primitives")
    c, u, v = (np.asarray(x, dtype=np.float64) for x in (primitive.centre_m, primitive.half_u_m, primitive.half_v_m))
    if primitive.shape is Shape.RECT:
        outline = np.array([c - u - v, c + u - v, c + u + v, c - u + v])
    else:
        t = np.linspace(0.0, 2.0 * np.pi, boundary_points, endpoint=False)[:, None]
        outline = c + np.cos(t) * u + np.sin(t) * v
    project = project_directions_px if primitive.at_infinity else project_points_px
    xy = project(camera, outline)
    if not np.isfinite(xy).all():
        raise ValueError("the primitive must lie entirely in front of the centre of projection")
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))
