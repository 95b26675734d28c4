"""An image observer's internal response to one interval: the energy of the relative motion its eye sees.

Each frame of an interval (linear colour, psyop.session.image_observer.frames) is taken into opponent channels
(:data:`OPPONENT`: luminance, weighted by :attr:`MotionStage.luminance_weight`; red-green and blue-yellow, weight
1). Between each two successive frames ``I_t``, ``I_t+1``, both blurred by the eye (psyop.session.image_observer.eye:
optics, then the neural blur of each pixel's eccentricity from the gaze of frame t) and further to the motion
stage's scale (``scale_deg``, added in quadrature), the change ``D = I_t+1 - I_t`` is split into what a local
translation explains and what it does not: at each pixel the translation ``d`` that best explains ``D`` within a
Gaussian window of sd ``window_deg`` (Lucas-Kanade, :data:`LK_STEPS` steps, each warping ``I_t+1`` back by the
translation so far; gradients and window sums over the channels) is removed, and the residual is squared,
weighted by the sensitivity at the pixel's eccentricity (zero within ``pursued_deg`` of either frame's gaze), and
summed over pixels (times the pixel's solid angle, deg^2) and channels. The interval's response is the mean over
its frame pairs, in contrast^2 deg^2. So a surface that moves as a whole adds little, while one surface sliding
over another, or one appearing from behind another, adds its energy; what does not change adds nothing, and two
intervals with the same frames have the same response.

The eccentricity-dependent blur is a geometric ladder of Gaussian widths (ratio :data:`LADDER_RATIO`); each pixel
interpolates between the two widths around its own. Only the part of the frame that changes (with a margin of
the widest blur and window) is processed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from psyop.session.image_observer.eye import EyeStage, eccentricity_deg, pixel_directions
from psyop.session.image_observer.frames import IntervalFrames

#: the ratio of neighbouring blur widths in the ladder of the eccentricity-dependent blur
LADDER_RATIO = 1.5
#: below this sd (pixels) a Gaussian blur is taken as none
MIN_SIGMA_PX = 0.2
#: the 2x2 systems of the local translation are regularised by this fraction of their largest trace
REGULARISATION = 1e-3
#: Lucas-Kanade steps of the local translation (each warps the later frame by the translation so far)
LK_STEPS = 3


#: linear RGB -> the opponent channels the motion stage reads: luminance (Rec. 709 weights), red-green, blue-yellow
OPPONENT = np.array([[0.2126, 0.7152, 0.0722], [0.5, -0.5, 0.0], [-0.25, -0.25, 0.5]])


@dataclass(frozen=True)
class MotionStage:
    """The relative-motion stage: the spatial scale it sees at (``scale_deg``, a Gaussian sd added to the eye's
    blur), the window a local translation is fitted over (``window_deg``, a Gaussian sd), the radius around
    the gaze that pursuit holds on the fovea (``pursued_deg``: the pursued target's own motion on the display is
    no motion on the retina, so changes within it of the gaze of either frame of a pair are not counted) and the
    weight of the luminance channel beside the two chromatic ones (weight 1)."""

    scale_deg: float
    window_deg: float
    pursued_deg: float
    luminance_weight: float

    def channels(self, images: np.ndarray) -> np.ndarray:
        """``images`` (..., 3) linear RGB as the weighted opponent channels (..., 3)."""
        weights = np.array([self.luminance_weight, 1.0, 1.0])
        return (images @ OPPONENT.T) * np.sqrt(weights)


def pixel_pitch_deg(directions: np.ndarray) -> float:
    """The angular pitch (deg) of neighbouring pixels at the image's centre."""
    h, w = directions.shape[0] // 2, directions.shape[1] // 2
    cos = float(np.clip(directions[h, w] @ directions[h, w + 1], -1.0, 1.0))
    return math.degrees(math.acos(cos))


def variable_blur(image: np.ndarray, sigma_px: np.ndarray) -> np.ndarray:
    """``image`` (H, W, C) blurred at each pixel by a Gaussian of that pixel's sd ``sigma_px`` (H, W),
    interpolated (linearly in log sd) between the two widths of the ladder around it."""
    from scipy.ndimage import gaussian_filter

    lo = max(float(sigma_px.min()), MIN_SIGMA_PX)
    hi = max(float(sigma_px.max()), lo)
    n = 1 + math.ceil(math.log(hi / lo) / math.log(LADDER_RATIO) - 1e-9) if hi > lo else 1
    widths = lo * LADDER_RATIO ** np.arange(n)
    blurred = np.stack([image if s <= MIN_SIGMA_PX else gaussian_filter(image, sigma=(s, s, 0), mode="nearest")
                        for s in widths])
    if n == 1:
        return blurred[0]
    position = np.clip(np.log(np.maximum(sigma_px, lo) / lo) / math.log(LADDER_RATIO), 0, n - 1)
    below = np.minimum(position.astype(np.int64), n - 2)
    frac = (position - below)[..., None]
    rows, cols = np.indices(sigma_px.shape)
    return (1.0 - frac) * blurred[below, rows, cols] + frac * blurred[below + 1, rows, cols]


def _translation(before: np.ndarray, after: np.ndarray, window_px: float) -> tuple[np.ndarray, np.ndarray]:
    """The per-pixel translation (dx, dy) (pixels) that best explains ``after - before`` within a Gaussian window
    of sd ``window_px`` (one Lucas-Kanade step; gradients and sums over the channels)."""
    from scipy.ndimage import gaussian_filter

    change = after - before
    gy, gx = np.gradient(0.5 * (after + before), axis=(0, 1))

    def window(x: np.ndarray) -> np.ndarray:
        return gaussian_filter(np.sum(x, axis=-1), sigma=window_px, mode="nearest")

    jxx, jxy, jyy = window(gx * gx), window(gx * gy), window(gy * gy)
    bx, by = window(gx * change), window(gy * change)
    ridge = REGULARISATION * max(float(np.max(jxx + jyy)), 1e-30)
    jxx, jyy = jxx + ridge, jyy + ridge
    det = jxx * jyy - jxy * jxy
    return -(jyy * bx - jxy * by) / det, -(jxx * by - jxy * bx) / det


def local_translation(before: np.ndarray, after: np.ndarray, window_px: float, steps: int = LK_STEPS
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The per-pixel translation ``(dx, dy)`` (pixels, x right, y down) of ``after`` (H, W, C) from ``before``
    within a Gaussian window of sd ``window_px``, and ``after`` warped back by it: ``steps`` Lucas-Kanade steps,
    each warping ``after`` back by the translation found so far."""
    from scipy.ndimage import map_coordinates

    rows, cols = np.indices(before.shape[:2], dtype=np.float64)
    dx = np.zeros(before.shape[:2])
    dy = np.zeros(before.shape[:2])
    warped = after
    for _ in range(steps):
        step_x, step_y = _translation(before, warped, window_px)
        dx, dy = dx + step_x, dy + step_y
        warped = np.stack([map_coordinates(after[..., c], [rows + dy, cols + dx], order=1, mode="nearest")
                           for c in range(after.shape[-1])], axis=-1)
    return dx, dy, warped


def residual_change(before: np.ndarray, after: np.ndarray, window_px: float, steps: int = LK_STEPS) -> np.ndarray:
    """``after - before`` (H, W, C) less the local translation that best explains it (see the module docstring):
    :func:`local_translation`'s ``after`` warped back, less ``before``."""
    return local_translation(before, after, window_px, steps)[2] - before


def changed_box(images: np.ndarray, margin_px: int) -> tuple[slice, slice]:
    """The rows and columns (with ``margin_px`` around) where any frame differs from the next."""
    moving = np.any(images[1:] != images[:-1], axis=(0, 3))
    rows, cols = np.flatnonzero(moving.any(axis=1)), np.flatnonzero(moving.any(axis=0))
    if rows.size == 0:
        return slice(0, 0), slice(0, 0)
    h, w = moving.shape
    return (slice(max(0, rows[0] - margin_px), min(h, rows[-1] + 1 + margin_px)),
            slice(max(0, cols[0] - margin_px), min(w, cols[-1] + 1 + margin_px)))


def interval_response(frames: IntervalFrames, eye: EyeStage, motion: MotionStage) -> float:
    """The interval's internal response (contrast^2 deg^2; see the module docstring)."""
    images = motion.channels(np.asarray(frames.images, dtype=np.float32)).astype(np.float32)
    _, height, width, _ = images.shape
    directions = pixel_directions(frames.pixel_to_ray, width, height)
    pitch_deg = pixel_pitch_deg(directions)
    widest_deg = float(np.hypot(eye.sigma_deg(np.array(180.0)), motion.scale_deg))
    rows, cols = changed_box(images, math.ceil(3.0 * (widest_deg + motion.window_deg) / pitch_deg) + 1)
    directions = directions[rows, cols]
    total = 0.0
    for t in range(len(images) - 1):
        eccentricity = eccentricity_deg(directions, frames.gaze[t])
        if eccentricity.size == 0:
            break
        sigma_px = np.hypot(eye.sigma_deg(eccentricity), motion.scale_deg) / pitch_deg
        pair = np.concatenate([images[t, rows, cols], images[t + 1, rows, cols]], axis=-1)
        seen = variable_blur(pair, sigma_px)
        residual = residual_change(seen[..., :3], seen[..., 3:], motion.window_deg / pitch_deg)
        weight = eye.weight(eccentricity)
        pursued = (eccentricity < motion.pursued_deg) | (eccentricity_deg(directions, frames.gaze[t + 1]) < motion.pursued_deg)
        weight[pursued] = 0.0
        total += float(np.sum(weight[..., None] * residual ** 2)) * pitch_deg ** 2
    return total / max(1, len(images) - 1)
