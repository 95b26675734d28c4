"""Exact ray-geometry predictions for frontoparallel discs and borders (float64, no GPU).

Used by the tests and benchmarks to check the renderer in pixels. A frontoparallel disc seen
through a frontoparallel display from any centre of projection is a similarity image of the
disc: a circle (an axis-aligned ellipse if the pixels are not square).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from psyop.optics.camera import EyeCamera

import numpy as np

from psyop.rendering.camera_math import project_directions_px, project_points_px
from psyop.rendering.scene import Primitive, Shape


@dataclass(frozen=True)
class ImageEllipse:
    """An axis-aligned ellipse in pixels: centre (x, y) and semi-axes (rx, ry)."""

    centre_px: tuple[float, float]
    radii_px: tuple[float, float]


def projected_disc(camera: EyeCamera, disc: Primitive) -> ImageEllipse:
    """The image of a frontoparallel disc (shape DISC, axes along x and y) in pixels; a disc at
    optical infinity is projected as directions (the centre of projection does not enter)."""
    if disc.shape is not Shape.DISC:
        raise ValueError("projected_disc needs a disc")
    c = np.array(disc.centre_m)
    project = project_directions_px if disc.at_infinity else project_points_px
    pts = project(camera, np.stack([c, c + disc.half_u_m, c + disc.half_v_m]))
    rx = float(np.linalg.norm(pts[1] - pts[0]))
    ry = float(np.linalg.norm(pts[2] - pts[0]))
    return ImageEllipse((float(pts[0, 0]), float(pts[0, 1])), (rx, ry))


def circle_overlap_area(r1: float, r2: float, distance: float) -> float:
    """Area of the intersection of two circles with radii r1, r2 whose centres are ``distance`` apart."""
    d = float(distance)
    if d >= r1 + r2:
        return 0.0
    if d <= abs(r1 - r2):
        return math.pi * min(r1, r2) ** 2
    a1 = r1 * r1 * math.acos(np.clip((d * d + r1 * r1 - r2 * r2) / (2 * d * r1), -1, 1))
    a2 = r2 * r2 * math.acos(np.clip((d * d + r2 * r2 - r1 * r1) / (2 * d * r2), -1, 1))
    k = 0.5 * math.sqrt(max((-d + r1 + r2) * (d + r1 - r2) * (d - r1 + r2) * (d + r1 + r2), 0.0))
    return a1 + a2 - k


def visible_back_area_px(camera: EyeCamera, back: Primitive, front: Primitive) -> float:
    """Area (px^2) of the back disc's image not covered by the nearer front disc's image.

    Pixels may be non-square: both ellipses share the same aspect (same similarity), so the
    computation runs in x-scaled coordinates where they are circles and is scaled back.
    """
    eb, ef = projected_disc(camera, back), projected_disc(camera, front)
    aspect = eb.radii_px[1] / eb.radii_px[0]
    rb, rf = eb.radii_px[0], ef.radii_px[0]
    dx = eb.centre_px[0] - ef.centre_px[0]
    dy = (eb.centre_px[1] - ef.centre_px[1]) / aspect
    overlap = circle_overlap_area(rb, rf, math.hypot(dx, dy))
    return (math.pi * rb * rb - overlap) * aspect


def border_x_px(camera: EyeCamera, surface: Primitive, y_px: np.ndarray, iterations: int = 6) -> np.ndarray:
    """Image x (px) of a frontoparallel surface's sinusoidal border at image rows ``y_px``.

    Solves, per y, for the local border point whose image has that y (Newton on the
    monotone map b -> y, exact for a frontoparallel plane after one step; a few more for safety).
    """
    if surface.border is None:
        raise ValueError("surface has no sinusoidal border")
    bd = surface.border
    c = np.array(surface.centre_m)
    u = np.array(surface.half_u_m)
    v = np.array(surface.half_v_m)
    y = np.asarray(y_px, dtype=np.float64)

    def image_of(b: np.ndarray) -> np.ndarray:
        a = bd.offset + bd.amplitude * np.sin(2 * np.pi * bd.cycles * 0.5 * (b + 1.0) + bd.phase_rad)
        pts = c + a[:, None] * u + b[:, None] * v
        return project_points_px(camera, pts)

    b = np.zeros_like(y)
    for _ in range(iterations):
        p0 = image_of(b)
        p1 = image_of(b + 1e-6)
        dy_db = (p1[:, 1] - p0[:, 1]) / 1e-6
        b = b - (p0[:, 1] - y) / dy_db
    return image_of(b)[:, 0]
