"""Visual angles measured in rendered frames (tests/rendering/test_visual_angles.py).

Only the rendered pixels and the camera's pixel-to-ray matrix enter: a solid white primitive
on black is rendered with the conventional camera of a display whose image is a flat
rectangle at optical infinity, so each pixel's value is its covered fraction and pixels are
equal areas of the tangent plane z = -1 seen from the centre of projection. The covered
region's moments in that plane give its centre and its axes exactly for a region bounded by a
conic (a uniform ellipse of semi-axes a, b has second moments a^2/4, b^2/4). Angles follow
from tangent-plane points by ray geometry.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from psyop.rendering import Renderer, Scene
from psyop.rendering.camera_math import crop_camera, project_points_px


@dataclass(frozen=True)
class Ellipse:
    """A covered region in the tangent plane z = -1 (x right, y up): centre, semi-axes a >= b and
    the unit direction of the a axis."""

    centre: np.ndarray
    a: float
    b: float
    major: np.ndarray

    def point(self, along_major: float, along_minor: float) -> np.ndarray:
        minor = np.array([-self.major[1], self.major[0]])
        return self.centre + along_major * self.major + along_minor * minor


def tangent_point_direction(p: np.ndarray) -> np.ndarray:
    d = np.array([p[0], p[1], -1.0])
    return d / np.linalg.norm(d)


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.atan2(np.linalg.norm(np.cross(a, b)), float(a @ b)))


def render_coverage(ctx: Any, camera: Any, scene: Scene, around_m: np.ndarray, half_px: int,
                    at_infinity: bool = False) -> tuple[np.ndarray, Any]:
    """Red-channel coverage of ``scene`` in a crop of ``camera`` centred on ``around_m`` (a head-space point,
    or a direction when ``at_infinity``), and the crop camera."""
    point = np.asarray(around_m, dtype=np.float64)
    if at_infinity:
        point = np.asarray(camera.centre_of_projection_m) + point
    c = project_points_px(camera, [point])[0]
    x0 = max(0, int(c[0]) - half_px)
    y0 = max(0, int(c[1]) - half_px)
    crop = crop_camera(camera, x0, y0, min(2 * half_px, camera.width_px - x0), min(2 * half_px, camera.height_px - y0))
    with Renderer(scene, ctx=ctx) as renderer:
        renderer.render(crop)
        image = renderer.image()
    coverage = image[..., 0].astype(np.float64)
    # the whole region must be inside the crop: its border rows and columns are empty
    assert coverage[0].max() == 0 and coverage[-1].max() == 0 and coverage[:, 0].max() == 0 and coverage[:, -1].max() == 0
    return coverage, crop


def tangent_ellipse(coverage: np.ndarray, camera: Any) -> Ellipse:
    """The covered region's moment ellipse in the tangent plane of ``camera`` (a flat image
    parallel to z = -1, conventional camera: tangent coordinates are affine in pixels)."""
    h, w = coverage.shape
    m = np.asarray(camera.pixel_to_ray, dtype=np.float64)
    assert abs(m[2, 0]) < 1e-15 and abs(m[2, 1]) < 1e-15, "the image plane must be frontoparallel"
    ys, xs = np.mgrid[0:h, 0:w]
    uv1 = np.stack([(xs + 0.5) / w, (ys + 0.5) / h, np.ones_like(xs, dtype=np.float64)], axis=-1)
    rays = uv1 @ m.T
    tx, ty = rays[..., 0] / -rays[..., 2], rays[..., 1] / -rays[..., 2]
    total = coverage.sum()
    cx, cy = (coverage * tx).sum() / total, (coverage * ty).sum() / total
    dx, dy = tx - cx, ty - cy
    cov = np.array([[(coverage * dx * dx).sum(), (coverage * dx * dy).sum()],
                    [(coverage * dx * dy).sum(), (coverage * dy * dy).sum()]]) / total
    # a pixel's coverage sits at its centre: add the box's own second moment (pitch^2 / 12) per axis
    pitch_x = abs(m[0, 0]) / w / abs(m[2, 2])
    pitch_y = abs(m[1, 1]) / h / abs(m[2, 2])
    cov += np.diag([pitch_x**2 / 12.0, pitch_y**2 / 12.0])
    values, vectors = np.linalg.eigh(cov)
    return Ellipse(np.array([cx, cy]), 2.0 * math.sqrt(values[1]), 2.0 * math.sqrt(values[0]), vectors[:, 1])


def centre_direction(coverage: np.ndarray, camera: Any) -> np.ndarray:
    """Direction of the covered region's centroid in the tangent plane (the projected centre of a
    frontoparallel disc: central projection between parallel planes is a similarity)."""
    return tangent_point_direction(tangent_ellipse(coverage, camera).centre)


def subtenses_deg(ellipse: Ellipse, facing: str) -> tuple[float, float]:
    """(radial, tangential) subtense of the region, read off its measured ellipse.

    Radial: between the region's two outline points on the meridian through its centre. Tangential,
    frontoparallel: the diameter across that meridian through the projected centre (the disc's own
    diameter). Tangential, eye-facing: across the great circle perpendicular to the meridian through
    the region's angular mid-point (the axis of its cone of directions)."""
    c = ellipse.centre
    radial = c / np.linalg.norm(c) if np.linalg.norm(c) > 1e-12 else ellipse.major
    tangential = np.array([-radial[1], radial[0]])
    if facing == "frontoparallel":
        r = (ellipse.a + ellipse.b) / 2.0
        ends = [(c + r * radial, c - r * radial), (c + r * tangential, c - r * tangential)]
        return tuple(angle_deg(tangent_point_direction(p), tangent_point_direction(q)) for p, q in ends)
    # eye-facing: the major axis is radial; its ends are the radial extremes
    sign = 1.0 if ellipse.major @ radial >= 0 else -1.0
    p1, p2 = c + sign * ellipse.a * ellipse.major, c - sign * ellipse.a * ellipse.major
    d1, d2 = tangent_point_direction(p1), tangent_point_direction(p2)
    axis = (d1 + d2) / np.linalg.norm(d1 + d2)
    q = axis[:2] / -axis[2]
    along = (q - c) @ (sign * ellipse.major)
    s = ellipse.b * math.sqrt(max(0.0, 1.0 - (along / ellipse.a) ** 2))
    minor = np.array([-ellipse.major[1], ellipse.major[0]])
    t1, t2 = tangent_point_direction(q + s * minor), tangent_point_direction(q - s * minor)
    return angle_deg(d1, d2), angle_deg(t1, t2)
