"""The former per-trial pieces of psyop.quality.measures (each trial's phases measured one at a time: its
angle errors, per-eye errors, precision sums and pursuit velocities computed phase by phase, then summarised),
kept outside production as the reference tests/quality/former_measures.py builds the former trial measures
from; the session-wide form in psyop.quality.measures is held to it exactly."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from psyop.optics.angles import angle_between_deg, fick_direction
from psyop.quality.samples import GazeGrid
from psyop.quality.target import target_positions_deg


def _err(az: np.ndarray, el: np.ndarray, taz: np.ndarray, tel: np.ndarray) -> np.ndarray:
    return np.asarray(angle_between_deg(fick_direction(az, el), fick_direction(taz, tel)), dtype=np.float64)


def _eye_errors(grid: GazeGrid, sel: np.ndarray, centre_deg: tuple[float, float], distance_m: float) -> dict:
    """Per eye the angle (deg) between its gaze normal and the line from its centre to the cross (at the
    plan's distance along the cross direction from the head origin); only eyes the tracker gives."""
    point = distance_m * fick_direction(*centre_deg)
    out = {}
    for eye, (az, el) in grid.eyes.items():
        to_target = point - grid.eye_centres_m[eye][sel]
        normal = fick_direction(az[sel], el[sel])
        ok = np.all(np.isfinite(to_target), axis=1) & np.all(np.isfinite(normal), axis=1)
        out[eye] = np.asarray(angle_between_deg(normal[ok], to_target[ok]), dtype=np.float64)
    return out


@dataclass
class _Precision:
    """Sums over contiguous fixation segments (runs of successive grid ticks, each with a valid sample
    outside a saccade): squared sample-to-sample displacements and their count, squared deviations from
    each segment's own mean and their degrees of freedom (a segment of n samples: n - 1 of each)."""

    s2s_sq_deg2: float = 0.0
    n_steps: int = 0
    deviation_sq_deg2: float = 0.0

    def add(self, index: np.ndarray, az: np.ndarray, el: np.ndarray) -> None:
        """Add the samples at grid ``index`` (ascending) with Fick ``az``, ``el`` (deg), split into segments
        wherever a tick is missing between two of them."""
        if len(index) == 0:
            return
        starts = np.flatnonzero(np.diff(index) != 1) + 1
        same = np.diff(index) == 1
        self.s2s_sq_deg2 += float(np.sum((np.diff(az)[same]) ** 2 + (np.diff(el)[same]) ** 2))
        self.n_steps += int(same.sum())
        segment = np.zeros(len(index), dtype=np.int64)
        segment[starts] = 1
        segment = np.cumsum(segment)
        counts = np.bincount(segment)
        for values in (az, el):
            means = np.bincount(segment, weights=values) / counts
            self.deviation_sq_deg2 += float(np.sum((values - means[segment]) ** 2))

    def measures(self) -> tuple[float, float]:
        """(RMS-S2S, SD) in deg, pooled over the segments: sqrt(sum of squared steps / steps) and
        sqrt(sum of squared deviations from the segment means / sum of (n - 1)); NaN with fewer than 2 steps."""
        if self.n_steps < 2:
            return math.nan, math.nan
        return math.sqrt(self.s2s_sq_deg2 / self.n_steps), math.sqrt(self.deviation_sq_deg2 / self.n_steps)


@dataclass
class _TrialParts:
    """What one trial's phases contribute, concatenated into its measures by :func:`_summary`."""

    fix_err: list[np.ndarray] = field(default_factory=list)
    fix_corr: list[np.ndarray] = field(default_factory=list)
    pur_err: list[np.ndarray] = field(default_factory=list)
    pur_corr: list[np.ndarray] = field(default_factory=list)
    precision: _Precision = field(default_factory=_Precision)
    per_eye: dict[str, list[np.ndarray]] = field(default_factory=lambda: {"left": [], "right": []})
    speed_ratio: list[np.ndarray] = field(default_factory=list)
    angle_diff: list[np.ndarray] = field(default_factory=list)
    turn: list[np.ndarray] = field(default_factory=list)
    pursuit_s: float = 0.0
    n_catch: int = 0
    #: the drift correction (az, el) in deg: median error over the last 0.25 s of the first cross phase
    offset: tuple[float, float] | None = None


@dataclass(frozen=True)
class _Samples:
    """The valid samples of one phase: ``sel`` (their indices into the grid, ascending), and their az, el (deg)
    and times (s)."""

    sel: np.ndarray
    az: np.ndarray
    el: np.ndarray
    t: np.ndarray




def _pursuit_phase(parts: _TrialParts, s: _Samples, target: Callable[[float], tuple[float, float]], t0: float,
                   v_e: np.ndarray, near_saccade: np.ndarray) -> None:
    """Add a pursuit phase's errors and, over its smooth samples, the eye's velocity against the target's
    (gain, direction difference, turning rate) to ``parts``; ``v_e``: the eye's velocity (deg/s) at them."""
    tpos = target_positions_deg(target, s.t - t0)
    parts.pur_err.append(_err(s.az, s.el, tpos[:, 0], tpos[:, 1]))
    if parts.offset is not None:
        parts.pur_corr.append(_err(s.az - parts.offset[0], s.el - parts.offset[1], tpos[:, 0], tpos[:, 1]))
    h = 1e-3
    ahead, behind = target_positions_deg(target, s.t - t0 + h), target_positions_deg(target, s.t - t0 - h)
    v_t = (ahead - behind) / (2 * h)
    a_t = (ahead - 2 * tpos + behind) / h**2
    smooth = (~near_saccade) & np.all(np.isfinite(v_e), axis=1) & (s.t >= t0 + 0.1)
    s_t = np.hypot(*v_t.T)
    good = smooth & (s_t > 1.0)
    # the eye's velocity along the target's (zero-mean noise does not bias it, unlike |v|)
    parts.speed_ratio.append(np.sum(v_e[good] * v_t[good], axis=1) / s_t[good] ** 2)
    parts.angle_diff.append(np.arctan2(v_t[good, 0] * v_e[good, 1] - v_t[good, 1] * v_e[good, 0],
                                       np.sum(v_t[good] * v_e[good], axis=1)))
    parts.turn.append((v_t[good, 0] * a_t[good, 1] - v_t[good, 1] * a_t[good, 0]) / s_t[good] ** 2)


def _stat(parts: list[np.ndarray], fn: Callable[[np.ndarray], np.floating | float]) -> float:
    """``fn`` of the concatenated ``parts``; NaN when they hold no value."""
    values = np.concatenate(parts) if parts else np.zeros(0)
    return float(fn(values)) if len(values) else math.nan


def _summary(parts: _TrialParts) -> dict[str, float]:
    """The accuracy, precision and pursuit measures of one trial's ``parts``."""
    out = dict(accuracy_fixation_mean_deg=_stat(parts.fix_err, np.mean),
               accuracy_fixation_max_deg=_stat(parts.fix_err, np.max),
               accuracy_fixation_corrected_mean_deg=_stat(parts.fix_corr, np.mean),
               accuracy_pursuit_mean_deg=_stat(parts.pur_err, np.mean),
               accuracy_pursuit_max_deg=_stat(parts.pur_err, np.max),
               accuracy_pursuit_corrected_mean_deg=_stat(parts.pur_corr, np.mean),
               accuracy_fixation_left_mean_deg=_stat(parts.per_eye["left"], np.mean),
               accuracy_fixation_right_mean_deg=_stat(parts.per_eye["right"], np.mean))
    rms, sd = parts.precision.measures()
    out.update(precision_rms_s2s_deg=rms, precision_sd_deg=sd)
    out["pursuit_gain"] = _stat(parts.speed_ratio, np.median)
    # the eye's velocity direction is the target's turned back by (turning rate x lag): lag = -angle / rate
    rate = _stat(parts.turn, np.median)
    out["pursuit_lag_s"] = (-_stat(parts.angle_diff, np.median) / rate) if math.isfinite(rate) and abs(rate) > 0.1 \
        else math.nan
    out["catch_up_saccades_per_s"] = parts.n_catch / parts.pursuit_s if parts.pursuit_s > 0 else math.nan
    return out


@dataclass(frozen=True)
class _SessionGaze:
    """One session's samples, events (``trial``/``phase`` filled in trial by trial) and what is derived from
    them once: the pymovements velocity (n, 2; deg/s) and the saccade masks of :func:`_saccade_masks`."""

    grid: GazeGrid
    events: pd.DataFrame
    velocity: np.ndarray
    in_saccade: np.ndarray
    near_saccade: np.ndarray
    #: the events' onsets (s), whether each is a fixation, and the trial (-1: none) and phase each began in
    #: (filled in trial by trial, written to ``events`` at the end: numpy, not a pandas write per phase)
    onset_s: np.ndarray
    is_fixation: np.ndarray
    event_trial: np.ndarray
    event_phase: np.ndarray


