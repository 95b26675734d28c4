"""The image observer's ordinal rule (``left_right_nearer``): which side of the border its own eye movements say
is nearer, from the interval's rendered frames.

The cue is ocular parallax's direction: the eye's nodal point lies in front of its centre of rotation, so when the
eye turns by a gaze shift ``g`` the nodal point moves the same way, and in the image a nearer surface shifts
against ``g`` relative to a farther one. In free viewing each frame is seen from a fixation of its own
(psyop.session.image_observer.frames.free_fixations); for each pair of successive frames the observer measures
the translation of the left and of the right half field (the pixels more than ``strip_deg`` left / right of the
view's vertical midline, where the border runs): one least-squares translation per half (Lucas-Kanade,
:data:`SHIFT_STEPS` steps, each warping the later frame back by the shift so far), over the three opponent
channels at weight 1 each (the ordinal study's textures are achromatic), after the eye's blur at each pixel's
eccentricity and the motion stage's scale, each pixel weighted by the sensitivity at its eccentricity from the
earlier frame's gaze. Pixels within three blur sds (and a pixel) of what is black in both frames (nothing drawn:
outside an aperture) are left out: an opening's edge is fixed on the display and does not move with either
surface, so it would pull a half field's shift towards none. The pair's evidence that the left side is nearer is
``s = -(d_left - d_right) . g / |g|`` (arcmin, the shifts and ``g`` in (azimuth, elevation) at the image's
centre pitch). A pair without a gaze shift, or frames that do not change, give ``s = 0``: where the stimulus
carries no cue (conventional rendering: the same frames whatever the gaze) the evidence is 0 and the answer a
coin toss. Reversed ocular parallax shifts the sides the other way: this rule then says the far side is nearer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from psyop.optics.angles import fick_angles_deg
from psyop.session.image_observer.eye import EyeStage, eccentricity_deg, pixel_directions
from psyop.session.image_observer.frames import IntervalFrames
from psyop.session.image_observer.response import OPPONENT, pixel_pitch_deg, variable_blur

#: Lucas-Kanade steps of each half field's translation
SHIFT_STEPS = 3
#: linear luminance below which a pixel counts as black (nothing drawn): its edge is left out of the half fields
BLACK = 0.02
#: the 2x2 systems are regularised by this fraction of their trace (a half field without texture: no shift)
RIDGE = 1e-6


def sampled_at_offset(image: np.ndarray, dx_px: float, dy_px: float) -> np.ndarray:
    """``image`` (H, W, C) read at each pixel plus (``dx_px``, ``dy_px``): bilinear, edges repeated outwards."""
    height, width = image.shape[:2]
    ix, iy = math.floor(dx_px), math.floor(dy_px)
    fx, fy = dx_px - ix, dy_px - iy
    rows = [np.clip(np.arange(height) + iy + k, 0, height - 1) for k in (0, 1)]
    cols = [np.clip(np.arange(width) + ix + k, 0, width - 1) for k in (0, 1)]
    top = (1.0 - fx) * image[rows[0]][:, cols[0]] + fx * image[rows[0]][:, cols[1]]
    bottom = (1.0 - fx) * image[rows[1]][:, cols[0]] + fx * image[rows[1]][:, cols[1]]
    return (1.0 - fy) * top + fy * bottom


def half_shift_px(before: np.ndarray, after: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """The translation (dx, dy) (pixels, x right, y down) of ``after`` (H, W, C) from ``before`` over the pixels of
    ``weight`` (H, W): :data:`SHIFT_STEPS` weighted least-squares steps, each warping ``after`` back by the shift
    so far."""
    gy, gx = np.gradient(before, axis=(0, 1))
    w = weight[..., None]
    jxx, jxy, jyy = float(np.sum(w * gx * gx)), float(np.sum(w * gx * gy)), float(np.sum(w * gy * gy))
    ridge = RIDGE * max(jxx + jyy, 1e-30)
    system = np.array([[jxx + ridge, jxy], [jxy, jyy + ridge]])
    shift = np.zeros(2)
    warped = after
    for _ in range(SHIFT_STEPS):
        change = warped - before
        step = -np.linalg.solve(system, [float(np.sum(w * gx * change)), float(np.sum(w * gy * change))])
        shift = shift + step
        warped = sampled_at_offset(after, float(shift[0]), float(shift[1]))
    return shift


def static_edge(luminance: np.ndarray, margin_px: int) -> np.ndarray:
    """(H, W) the pixels within ``margin_px`` (city-block) of what is black in both frames (luminance (2, H, W)
    below :data:`BLACK`: nothing drawn there, e.g. outside an aperture)."""
    from scipy.ndimage import binary_dilation

    black = np.max(luminance, axis=0) < BLACK
    return black if not black.any() else binary_dilation(black, iterations=margin_px)


@dataclass(frozen=True)
class SeenPair:
    """Frames ``k`` and ``k + 1`` as the eye sees them: the gaze shift (deg, Fick [azimuth, elevation]) and its
    size, each pixel's direction, pitch (deg) and eccentricity (deg), the two frames' opponent channels after the
    eye's blur and ``scale_deg`` (``before``, ``after``: (H, W, 3)), the blur (px) and the pixels near what is black
    in both frames (``edge``)."""

    shift_deg: np.ndarray
    size_deg: float
    directions: np.ndarray
    pitch_deg: float
    eccentricity_deg: np.ndarray
    before: np.ndarray
    after: np.ndarray
    edge: np.ndarray


def seen_pair(frames: IntervalFrames, k: int, eye: EyeStage, scale_deg: float) -> SeenPair | None:
    """Frames ``k`` and ``k + 1`` as seen (:class:`SeenPair`); None without a gaze shift or a change between them."""
    shift_deg = np.array(fick_angles_deg(frames.gaze[k + 1]), dtype=np.float64) - \
        np.array(fick_angles_deg(frames.gaze[k]), dtype=np.float64)
    size = float(np.hypot(*shift_deg))
    if size == 0.0 or np.array_equal(frames.images[k], frames.images[k + 1]):
        return None
    images = np.asarray(frames.images[k:k + 2], dtype=np.float64) @ OPPONENT.T
    _, height, width, _ = images.shape
    directions = pixel_directions(frames.pixel_to_ray, width, height)
    pitch_deg = pixel_pitch_deg(directions)
    eccentricity = eccentricity_deg(directions, frames.gaze[k])
    sigma_px = np.hypot(eye.sigma_deg(eccentricity), scale_deg) / pitch_deg
    seen = variable_blur(np.concatenate([images[0], images[1]], axis=-1), sigma_px)
    edge = static_edge(images[..., 0], math.ceil(3.0 * float(sigma_px.max())) + 1)
    return SeenPair(shift_deg, size, directions, pitch_deg, eccentricity, seen[..., :3], seen[..., 3:], edge)


def pair_evidence_arcmin(frames: IntervalFrames, k: int, eye: EyeStage, scale_deg: float, strip_deg: float) -> float:
    """The evidence (arcmin) of frames ``k`` and ``k + 1`` that the left side is nearer (see the module docstring)."""
    pair = seen_pair(frames, k, eye, scale_deg)
    if pair is None:
        return 0.0
    height, width = pair.edge.shape
    azimuth_deg = np.asarray(fick_angles_deg(pair.directions)[0]) - \
        float(fick_angles_deg(pair.directions[height // 2, width // 2])[0])
    weight = eye.weight(pair.eccentricity_deg) * ~pair.edge
    left = half_shift_px(pair.before, pair.after, weight * (azimuth_deg < -strip_deg))
    right = half_shift_px(pair.before, pair.after, weight * (azimuth_deg > strip_deg))
    relative_deg = (left - right) * pair.pitch_deg * np.array([1.0, -1.0])  # pixels (x right, y down) -> (az, el)
    return float(-(relative_deg @ pair.shift_deg) / pair.size_deg * 60.0)


def interval_evidence_arcmin(frames: IntervalFrames, eye: EyeStage, scale_deg: float, strip_deg: float) -> list[float]:
    """Each successive pair's evidence (arcmin) that the left side is nearer."""
    return [pair_evidence_arcmin(frames, k, eye, scale_deg, strip_deg) for k in range(len(frames.images) - 1)]


def p_left(evidence_arcmin: list[float], noise_arcmin: float, lapse: float) -> float:
    """p(answer left): each pair's evidence plus Gaussian noise of sd ``noise_arcmin``, summed; left when the sum
    is positive; a guess at rate ``lapse``: ``lapse / 2 + (1 - lapse) Phi(sum / (noise sqrt(n)))``."""
    n = max(1, len(evidence_arcmin))
    z = float(np.sum(evidence_arcmin)) / (noise_arcmin * math.sqrt(n))
    return 0.5 * lapse + (1.0 - lapse) * 0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))
