"""Frame reuse: skip a frame when the gaze change since the last rendered frame cannot move
any scene point by more than a tolerance (default 0.01 px).

Bound. The display's image rectangle is fixed in head space at distance d. When the centre of
projection moves by delta, a point at distance z from it changes direction by at most
|delta| / (z - |delta|), and a point of the display image by |delta| / (d - |delta|); its image
position, measured against the fixed display, therefore moves by at most

    |delta| * max_z |1/(z - |delta|) - 1/d|  radians  (1/d = 0 for an image at infinity)

over the scene's depth range [z_min, z_max] seen from the last rendered centre. Multiplied by
the largest pixels-per-radian anywhere in the image this bounds the shift in pixels. The pixel
grid itself must be unchanged: the display part of ``pixel_to_ray`` (its first two columns),
the eye, the image size and the scene must all match, otherwise the frame is rendered.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from psyop.optics.camera import EyeCamera

import numpy as np

from psyop.rendering.camera_math import max_px_per_rad


@dataclass(frozen=True)
class ReuseDecision:
    """Whether a frame may reuse the last image, and the shift bound (px) that decided it."""

    skip: bool
    bound_px: float
    reason: str


def shift_bound_px(
    delta_m: float, depth_min_m: float, depth_max_m: float, image_distance_m: float, px_per_rad: float
) -> float:
    """Largest image shift (px) of any point with distance in [depth_min_m, depth_max_m] when
    the centre of projection moves by ``delta_m`` (see the module docstring)."""
    if delta_m == 0.0:
        return 0.0
    z_min = depth_min_m - delta_m
    if not (z_min > 0.0):
        return math.inf
    inv_d = 0.0 if math.isinf(image_distance_m) else 1.0 / max(image_distance_m - delta_m, 1e-12)
    inv_far = 0.0 if math.isinf(depth_max_m) else 1.0 / max(depth_max_m - delta_m, z_min)
    worst = max(abs(1.0 / z_min - inv_d), abs(inv_far - inv_d))
    return delta_m * worst * px_per_rad


def decide_reuse(
    last_camera: EyeCamera | None,
    new_camera: EyeCamera,
    depth_range_m: tuple[float, float] | Callable[[], tuple[float, float]],
    tolerance_px: float = 0.01,
) -> ReuseDecision:
    """Decide whether ``new_camera`` may reuse the frame rendered with ``last_camera``.

    The image distance d comes from the cameras themselves: ``pixel_to_ray``'s third column is
    (display origin - P) / d, so it changes by -delta / d when P moves by delta (d = inf: no
    change). ``depth_range_m``: the scene's (nearest, farthest) distance from the last centre of
    projection, or a function that computes it, called only when the bound needs it (the camera
    checks passed and the centre moved).

    Examples
    --------
    >>> from psyop.optics import VIVE_PRO, make_eye_camera
    >>> cam = make_eye_camera(VIVE_PRO, "right", (0.0, 0.0, -1.0), 0.064, 0.0076916, "conventional")
    >>> decide_reuse(cam, cam, lambda: (1.0, 2.0)).skip
    True
    """
    if last_camera is None:
        return ReuseDecision(False, math.inf, "first frame")
    if (last_camera.width_px, last_camera.height_px) != (new_camera.width_px, new_camera.height_px) or str(
        last_camera.eye
    ) != str(new_camera.eye):
        return ReuseDecision(False, math.inf, "image changed")
    m_old = np.asarray(last_camera.pixel_to_ray, dtype=np.float64)
    m_new = np.asarray(new_camera.pixel_to_ray, dtype=np.float64)
    if not np.allclose(m_old[:, :2], m_new[:, :2], rtol=1e-12, atol=0.0):
        return ReuseDecision(False, math.inf, "display moved")
    shift = np.asarray(new_camera.centre_of_projection_m, dtype=np.float64) - last_camera.centre_of_projection_m
    delta = float(np.linalg.norm(shift))
    column_change = m_new[:, 2] - m_old[:, 2]
    scale = float(np.max(np.abs(m_old)))
    inv_d = 0.0 if delta == 0.0 else -float(column_change @ shift) / (delta * delta)
    if np.linalg.norm(column_change + inv_d * shift) > 1e-12 * scale or inv_d < 0.0:
        return ReuseDecision(False, math.inf, "pixel grid moved")
    d_m = math.inf if inv_d * scale <= 1e-15 else 1.0 / inv_d
    if delta == 0.0:
        bound = 0.0  # shift_bound_px of no shift, whatever the depths
    else:
        near_m, far_m = depth_range_m() if callable(depth_range_m) else depth_range_m
        bound = shift_bound_px(delta, near_m, far_m, d_m, max_px_per_rad(new_camera))
    return ReuseDecision(bound <= tolerance_px, bound, "within tolerance" if bound <= tolerance_px else "moved")

