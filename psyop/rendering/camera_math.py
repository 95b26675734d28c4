"""Float64 helpers on the optics :class:`EyeCamera` contract that the renderer needs.

Only the contract's fields are used (``centre_of_projection_m``, ``pixel_to_ray``,
``projection``, ``width_px``, ``height_px``, ``valid``), so any object with them works.
"""

from __future__ import annotations

import dataclasses
import math
from psyop.optics.camera import EyeCamera

import numpy as np
from numpy.typing import ArrayLike


def camera_is_usable(camera: EyeCamera) -> bool:
    """True when the camera is flagged valid and all its numbers are finite and non-degenerate."""
    try:
        cop = np.asarray(camera.centre_of_projection_m, dtype=np.float64)
        ray = np.asarray(camera.pixel_to_ray, dtype=np.float64)
    except (TypeError, ValueError, AttributeError):
        return False
    if cop.shape != (3,) or ray.shape != (3, 3):
        return False
    if not (bool(getattr(camera, "valid", True)) and np.all(np.isfinite(cop)) and np.all(np.isfinite(ray))):
        return False
    det = float(np.linalg.det(ray))
    return math.isfinite(det) and abs(det) > 1e-300


def near_far_m(camera: EyeCamera) -> tuple[float, float]:
    """Clip distances recovered from an OpenGL projection; (0, inf) when it is missing or odd."""
    try:
        p = np.asarray(camera.projection, dtype=np.float64)
        a, b = p[2, 2], p[2, 3]
        near, far = b / (a - 1.0), b / (a + 1.0)
    except (AttributeError, IndexError, TypeError, ValueError, ZeroDivisionError):
        return (0.0, math.inf)
    if not (math.isfinite(near) and math.isfinite(far) and 0.0 < near < far):
        return (0.0, math.inf)
    return (float(near), float(far))


def project_points_px(camera: EyeCamera, points_head_m: ArrayLike) -> np.ndarray:
    """(n, 3) head-space points -> (n, 2) pixel positions (x right, y down) by inverting
    ``pixel_to_ray``: exact ray geometry, no projection matrix. NaN behind the centre."""
    pts = np.atleast_2d(np.asarray(points_head_m, dtype=np.float64))
    rel = pts - np.asarray(camera.centre_of_projection_m, dtype=np.float64)
    uvw = np.linalg.solve(np.asarray(camera.pixel_to_ray, dtype=np.float64), rel.T).T
    with np.errstate(divide="ignore", invalid="ignore"):
        u = uvw[:, 0] / uvw[:, 2]
        v = uvw[:, 1] / uvw[:, 2]
    out = np.stack([u * camera.width_px, v * camera.height_px], axis=-1)
    out[~(uvw[:, 2] > 0)] = np.nan
    return out


def project_directions_px(camera: EyeCamera, directions_head: np.ndarray) -> np.ndarray:
    """(n, 3) head-space directions (points at infinity, w = 0) -> (n, 2) pixel positions; the
    centre of projection does not enter (zero parallax). NaN for directions pointing backwards."""
    d = np.atleast_2d(np.asarray(directions_head, dtype=np.float64))
    return project_points_px(camera, d + np.asarray(camera.centre_of_projection_m, dtype=np.float64))


def pixel_rays(camera: EyeCamera, xy_px: np.ndarray) -> np.ndarray:
    """(n, 2) pixel positions -> (n, 3) unit ray directions in head space."""
    xy = np.atleast_2d(np.asarray(xy_px, dtype=np.float64))
    uv1 = np.stack([xy[:, 0] / camera.width_px, xy[:, 1] / camera.height_px, np.ones(len(xy))], axis=-1)
    d = uv1 @ np.asarray(camera.pixel_to_ray, dtype=np.float64).T
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def max_px_per_rad(camera: EyeCamera) -> float:
    """An upper bound on pixels per radian anywhere in the image (largest at the image corners
    of a planar image): (1 + t^2) / (tangent per pixel), t the largest corner tangent."""
    m = np.asarray(camera.pixel_to_ray, dtype=np.float64)
    corners = np.array([[u, v, 1.0] for u in (0.0, 1.0) for v in (0.0, 1.0)]) @ m.T
    depth = -corners[:, 2]
    tx = corners[:, 0] / depth
    ty = corners[:, 1] / depth
    t2 = float(np.max(tx**2 + ty**2))
    per_px = min(abs(m[0, 0] / m[2, 2]) / camera.width_px, abs(m[1, 1] / m[2, 2]) / camera.height_px)
    return (1.0 + t2) / per_px


def crop_camera(camera: EyeCamera, x0_px: int, y0_px: int, width_px: int, height_px: int) -> EyeCamera:
    """The same camera restricted to a pixel window: rays and projection are those of the
    full image, so a crop renders exactly the corresponding pixels of the full frame."""
    if width_px <= 0 or height_px <= 0:
        raise ValueError("crop size must be positive")
    w, h = camera.width_px, camera.height_px
    s = np.array([[width_px / w, 0.0, x0_px / w], [0.0, height_px / h, y0_px / h], [0.0, 0.0, 1.0]])
    ray = np.asarray(camera.pixel_to_ray, dtype=np.float64) @ s
    # NDC of the crop: x_ndc' = (x_ndc - cx) * w / width, with cx the crop centre in full NDC.
    cx = (2.0 * (x0_px + width_px / 2.0) / w) - 1.0
    cy = 1.0 - (2.0 * (y0_px + height_px / 2.0) / h)
    proj = np.asarray(camera.projection, dtype=np.float64)
    # clip' = ndc applied per w: x' = (x - cx * w_clip) * sx
    crop_proj = proj.copy()
    crop_proj[0] = (proj[0] - cx * proj[3]) * (w / width_px)
    crop_proj[1] = (proj[1] - cy * proj[3]) * (h / height_px)
    return dataclasses.replace(camera, pixel_to_ray=ray, projection=crop_proj, width_px=int(width_px),
                               height_px=int(height_px))
