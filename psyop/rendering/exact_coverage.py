"""Exact pixel coverage of a straight-edged primitive (float64, no GPU).

A planar parallelogram entirely in front of the centre of projection projects through the
display to a convex quadrilateral (straight edges stay straight under a central projection).
Its exact coverage of each pixel square is the area of quadrilateral n square, computed here by
clipping the quadrilateral to each pixel (Sutherland-Hodgman). Used to measure the error of the
anti-aliasing effort spent on straight background edges (benchmarks/bench_frame_path.py).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from psyop.rendering.camera_math import project_points_px
from psyop.rendering.scene import Primitive, Shape


def projected_corners_px(camera: Any, rect: Primitive) -> np.ndarray:
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
