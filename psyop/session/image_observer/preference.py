"""The image observer's preference rule (``pairwise_preference``): of two intervals, the one whose frames carry
more evidence of depth from the observer's own eye movements is preferred.

The rule is a model of preference, a hypothesis, not a fit: it assumes that the impression of realistic depth
grows with the relative image motion that depth causes when the eye moves (ocular parallax, the cue the ordinal
rule reads, psyop.session.image_observer.ordinal), whatever that motion's direction. Nothing in it is fitted to
the realism study; its noise is the ordinal rule's stated ``shift_noise_arcmin``.

In free viewing each frame is seen from a fixation of its own (psyop.session.image_observer.frames). For each
pair of successive frames (:func:`pair_shifts`), after the eye's blur at each pixel's eccentricity from the
earlier frame's gaze and the motion stage's scale ``scale_deg``, in the three opponent channels at weight 1 each
(the realism study's textures are achromatic): the translation the whole field shares is measured and removed
(one least-squares translation, psyop.session.image_observer.ordinal.half_shift_px, over every pixel weighted by
the sensitivity at its eccentricity), then each pixel's local translation is measured (Lucas-Kanade within a
Gaussian window of sd ``window_deg``, psyop.session.image_observer.response.local_translation) and converted to a
change of (azimuth, elevation) through the image's own mapping at that pixel; its component along the gaze shift
``g``, less the pair's weighted mean and divided by ``|g|``, is the pixel's relative shift (arcmin per deg of
gaze shift). Each pixel is weighted by the sensitivity at its eccentricity and by how well a translation is
determined there in both directions (:func:`corner_strength`); pixels within three blur sds (and a pixel) of
what is black in both frames are left out, as in the ordinal rule. A pair without a gaze shift, or frames that
do not change, carry no evidence.

Ocular parallax gives a surface the same relative shift per degree of gaze shift in every pair (it follows the
surface's depth), while a measurement's error changes from pair to pair. The interval's depth evidence is
therefore what the pairs' relative shifts share: the mean over every two pairs of the weighted mean product of
their relative shifts (pixels weighted by the geometric mean of the two pairs' weights), ``c`` (arcmin/deg)^2,
as ``sign(c) sqrt(|c|)`` times the pairs' mean ``|g|`` (arcmin; :func:`interval_depth_arcmin`). An interval with
fewer than two pairs that carry evidence has evidence 0.

Decision: each interval's evidence plus Gaussian noise of sd ``noise_arcmin``; the larger is preferred, so
interval a is preferred with probability ``lapse / 2 + (1 - lapse) Phi((E_a - E_b) / (noise sqrt 2))``.
Two intervals with the same frames have the same evidence: p = 1/2. Conventional rendering draws the same frames
at every fixation: its evidence is 0. Ocular and reversed ocular parallax move the surfaces by the same amounts
in opposite directions, which the products of two pairs do not tell apart: the rule reads them alike.

What the evidence measures at the default resolution is checked by benchmarks/bench_image_observer.py: beside the
realism study's scene it measures a control whose targets all lie at one depth (no relative depth between them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from psyop.optics.angles import fick_angles_deg
from psyop.session.image_observer.eye import EyeStage
from psyop.session.image_observer.frames import IntervalFrames
from psyop.session.image_observer.ordinal import half_shift_px, sampled_at_offset, seen_pair
from psyop.session.image_observer.response import local_translation


def corner_strength(image: np.ndarray, window_px: float) -> np.ndarray:
    """(H, W) the smaller eigenvalue of the structure tensor of ``image`` (H, W, C; gradients summed over the
    channels) within a Gaussian window of sd ``window_px``: how well a local translation is determined there in
    both directions (an edge alone determines only its normal component: none)."""
    from scipy.ndimage import gaussian_filter

    gy, gx = np.gradient(image, axis=(0, 1))

    def window(x: np.ndarray) -> np.ndarray:
        return gaussian_filter(np.sum(x, axis=-1), sigma=window_px, mode="nearest")

    jxx, jxy, jyy = window(gx * gx), window(gx * gy), window(gy * gy)
    return np.maximum(0.5 * (jxx + jyy - np.sqrt((jxx - jyy) ** 2 + 4.0 * jxy * jxy)), 0.0)


def angular_shift_along_arcmin(directions: np.ndarray, dx_px: np.ndarray, dy_px: np.ndarray,
                               unit: np.ndarray) -> np.ndarray:
    """(H, W) each pixel's translation (``dx_px``, ``dy_px``; x right, y down) as a change of (azimuth, elevation)
    through the image's own mapping at that pixel (``directions`` (H, W, 3): the pixel grid is not uniform in
    angle), along the unit (azimuth, elevation) vector ``unit`` (arcmin)."""
    azimuth_deg, elevation_deg = (np.asarray(a, dtype=np.float64) for a in fick_angles_deg(directions))
    d_az_dy, d_az_dx = np.gradient(azimuth_deg)
    d_el_dy, d_el_dx = np.gradient(elevation_deg)
    d_az = d_az_dx * dx_px + d_az_dy * dy_px
    d_el = d_el_dx * dx_px + d_el_dy * dy_px
    return (d_az * float(unit[0]) + d_el * float(unit[1])) * 60.0


@dataclass(frozen=True)
class PairShifts:
    """One pair of successive frames: each pixel's local translation along the gaze shift less the pair's
    weighted mean, per degree of gaze shift (``relative`` (H, W), arcmin/deg), the pixels' ``weight`` (H, W) and the
    gaze shift's size (deg)."""

    relative: np.ndarray
    weight: np.ndarray
    shift_deg: float


def pair_shifts(frames: IntervalFrames, k: int, eye: EyeStage, scale_deg: float, window_deg: float
                ) -> PairShifts | None:
    """Frames ``k`` and ``k + 1``'s relative shifts (see the module docstring); None without a gaze shift, without
    a change between the frames or without any weight."""
    pair = seen_pair(frames, k, eye, scale_deg)
    if pair is None:
        return None
    before, after, edge, eccentricity = pair.before, pair.after, pair.edge, pair.eccentricity_deg
    window_px = window_deg / pair.pitch_deg
    common_px = half_shift_px(before, after, eye.weight(eccentricity) * ~edge)  # what every surface shares
    dx, dy, _ = local_translation(before, sampled_at_offset(after, float(common_px[0]), float(common_px[1])),
                                  window_px)
    along_arcmin = angular_shift_along_arcmin(pair.directions, dx, dy, pair.shift_deg / pair.size_deg)
    weight = eye.weight(eccentricity) * corner_strength(before, window_px) * ~edge
    total = float(np.sum(weight))
    if total <= 0.0:
        return None
    weight = weight / total
    mean = float(np.sum(weight * along_arcmin))
    return PairShifts((along_arcmin - mean) / pair.size_deg, weight, pair.size_deg)


def interval_depth_arcmin(frames: IntervalFrames, eye: EyeStage, scale_deg: float, window_deg: float) -> float:
    """The interval's depth evidence (arcmin; see the module docstring)."""
    pairs = [pair for k in range(len(frames.images) - 1)
             if (pair := pair_shifts(frames, k, eye, scale_deg, window_deg)) is not None]
    products = []
    for i, first in enumerate(pairs):
        for second in pairs[i + 1:]:
            weight = np.sqrt(first.weight * second.weight)
            total = float(np.sum(weight))
            if total > 0.0:  # pixels weighted in both pairs
                products.append(float(np.sum(weight * first.relative * second.relative)) / total)
    if not products:
        return 0.0
    consistent = float(np.mean(products))  # (arcmin/deg)^2: what the pairs' relative shifts share
    mean_shift_deg = float(np.mean([pair.shift_deg for pair in pairs]))
    return math.copysign(math.sqrt(abs(consistent)), consistent) * mean_shift_deg


def p_first_preferred(first_arcmin: float, second_arcmin: float, noise_arcmin: float, lapse: float) -> float:
    """p(the first interval is preferred) from each interval's evidence (see the module docstring)."""
    z = (first_arcmin - second_arcmin) / (noise_arcmin * math.sqrt(2.0))
    return 0.5 * lapse + (1.0 - lapse) * 0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))
