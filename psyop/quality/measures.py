"""Per-trial gaze data quality in degrees, against the target the participant was asked
to look at (rebuilt with :func:`psyop.session.loop.fixation_plan` from the trial row and the phase timing:
phase k starts at ``trial_start_s`` plus the durations before it; exact on the virtual clock, within a
frame of it on a real one).

Measures (:data:`TRIAL_MEASURES`): data loss against the nominal rate and the longest gap; accuracy
(mean and max angular error) on fixation (cross) and pursuit phases, before and after drift correction
(the trial's median error over the last 0.25 s of its first cross phase removed); precision (RMS-S2S and SD
as pymovements' ``rms_s2s`` and ``std_rms``, within each contiguous fixation segment of a fixation phase:
successive grid ticks with valid samples outside saccades; pooled over the segments: :class:`_Precision`);
pursuit gain (median eye velocity along the target's over its speed, smooth samples from 0.1 s into a pursuit phase), lag (median angle between eye and target
velocity over the target velocity's turning rate) and catch-up saccades per second of pursuit.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from psyop.optics.angles import angle_between_deg, fick_direction
from psyop.quality.events import EventMethod, detect_events
from psyop.quality.samples import GazeGrid
from psyop.quality.target import loop_config, target_positions_deg, trial_phases
from psyop.session.gaze.plan import FixationPlan
from psyop.session.loop import LoopConfig
from psyop.session.plan import SessionPlan
from psyop.session.rows import TrialRow

TRIAL_MEASURES: dict[str, str] = {
    "data_loss_share": "share of the samples expected at the nominal rate that are missing or invalid",
    "longest_gap_s": "longest stretch without a valid sample (s)",
    "accuracy_fixation_mean_deg": "mean angular error on the cross (deg)",
    "accuracy_fixation_max_deg": "largest angular error on the cross (deg)",
    "accuracy_fixation_corrected_mean_deg": "mean error on the cross after drift correction (deg)",
    "accuracy_fixation_left_mean_deg": "mean error of the left eye's gaze normal to the cross, from its centre (deg)",
    "accuracy_fixation_right_mean_deg": "mean error of the right eye's gaze normal to the cross, from its centre (deg)",
    "accuracy_pursuit_mean_deg": "mean angular error to the pursuit target (deg)",
    "accuracy_pursuit_max_deg": "largest angular error to the pursuit target (deg)",
    "accuracy_pursuit_corrected_mean_deg": "mean error to the pursuit target after drift correction (deg)",
    "precision_rms_s2s_deg": "RMS sample-to-sample displacement on the cross, within fixation segments (deg)",
    "precision_sd_deg": "radial SD of the samples on the cross about each fixation segment's mean, pooled (deg)",
    "pursuit_gain": "median eye velocity along the target's / target speed in smooth pursuit",
    "pursuit_lag_s": "how late the eye's velocity follows the target's (s)",
    "catch_up_saccades_per_s": "saccades per second of pursuit",
    "n_fixations": "fixations (pymovements I-VT) in the trial",
    "n_saccades": "saccades (pymovements microsaccades detector) in the trial",
    # the session's gaze validation that speaks for the trial (psyop.quality.validation; NaN: none)
    "validation_mean_error_deg": "mean over the validation's points of their mean angular error (deg)",
    "validation_max_error_deg": "largest angular error of any sample of the validation (deg)",
    "validation_precision_rms_s2s_deg": "mean over the validation's points of RMS sample-to-sample (deg)",
    "validation_precision_sd_deg": "mean over the validation's points of the samples' SD (deg)",
}


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


def _span(t_s: np.ndarray, start_s: float, end_s: float) -> slice:
    """The samples of ascending ``t_s`` in ``[start_s, end_s)``, as a slice (empty for a non-finite bound)."""
    if not (math.isfinite(start_s) and math.isfinite(end_s)):
        return slice(0, 0)
    return slice(int(np.searchsorted(t_s, start_s, side="left")), int(np.searchsorted(t_s, end_s, side="left")))


def _saccade_masks(t_s: np.ndarray, events: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """(in a saccade: ``onset_s <= t <= offset_s`` of a non-fixation event, within 2 samples of one) per
    sample of ascending ``t_s``: a velocity next to a saccade still carries part of it."""
    bounds = events.loc[events["name"] != "fixation", ["onset_s", "offset_s"]].to_numpy(dtype=np.float64)
    first = np.searchsorted(t_s, bounds[:, 0], side="left")  # each saccade's samples: [first, last)
    last = np.searchsorted(t_s, bounds[:, 1], side="right")
    some = first < last
    depth = np.zeros(len(t_s) + 1, dtype=np.int64)
    np.add.at(depth, first[some], 1)
    np.add.at(depth, last[some], -1)
    in_saccade = np.cumsum(depth[:-1]) > 0
    near_saccade = in_saccade.copy()
    for k in (1, 2):
        near_saccade[k:] |= in_saccade[:-k]
        near_saccade[:-k] |= in_saccade[k:]
    return in_saccade, near_saccade


def _loss_measures(grid: GazeGrid, window: slice, start_s: float, end_s: float) -> dict[str, float | int]:
    """Valid and expected sample counts, data loss share and longest gap of one trial's ``window``."""
    expected = max(1, int(round((end_s - start_s) * grid.rate_hz))) if math.isfinite(grid.rate_hz) else 0
    valid_t = grid.t_s[window][grid.valid[window]]
    edges = np.concatenate([[start_s], valid_t, [end_s]])
    return {"n_samples_valid": int(len(valid_t)), "n_samples_expected": expected,
            "data_loss_share": max(0.0, 1.0 - len(valid_t) / expected) if expected else 1.0,
            "longest_gap_s": float(np.max(np.diff(edges)))}


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


def _cross_phase(parts: _TrialParts, grid: GazeGrid, s: _Samples, fplan: FixationPlan, p_end: float,
                 in_saccade: np.ndarray, recalibration: bool = True) -> None:
    """Add a cross (or static fixation target) phase's errors (binocular, drift corrected, per eye) and still
    samples to ``parts``; only a drift recalibration (``recalibration``) measures the drift offset."""
    taz, tel = np.full(len(s.t), fplan.centre_deg[0]), np.full(len(s.t), fplan.centre_deg[1])
    if parts.offset is None and recalibration:
        last = s.t >= p_end - 0.25
        parts.offset = (float(np.median(s.az[last] - taz[last])), float(np.median(s.el[last] - tel[last]))) \
            if last.any() else None
    parts.fix_err.append(_err(s.az, s.el, taz, tel))
    for eye, errors in _eye_errors(grid, s.sel, fplan.centre_deg, fplan.distance_m).items():
        parts.per_eye[eye].append(errors)
    if parts.offset is not None:
        parts.fix_corr.append(_err(s.az - parts.offset[0], s.el - parts.offset[1], taz, tel))
    still = ~in_saccade[s.sel]
    parts.precision.add(s.sel[still], s.az[still], s.el[still])


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


def _trial_row(session: _SessionGaze, row: TrialRow, plan: SessionPlan, config: LoopConfig) -> dict[str, object]:
    """One trial's measures; marks the events that began in it with its trial number and phase."""
    grid = session.grid
    start, end = float(row["trial_start_s"]), float(row["trial_end_s"])
    window = _span(grid.t_s, start, end)  # the grid and the event onsets ascend: spans, not masks
    out: dict[str, object] = {"trial": int(row["trial"]), **_loss_measures(grid, window, start, end)}
    parts = _TrialParts()
    for p in trial_phases(plan, row, config):
        phase = _span(grid.t_s, p.start_s, p.end_s)
        first, last = max(window.start, phase.start), min(window.stop, phase.stop)
        sel = first + np.flatnonzero(grid.valid[first:last]) if last > first else np.zeros(0, dtype=np.int64)
        ev = _span(session.onset_s, p.start_s, p.end_s)
        session.event_trial[ev], session.event_phase[ev] = int(row["trial"]), p.phase.name
        s = _Samples(sel, grid.az_deg[sel], grid.el_deg[sel], grid.t_s[sel])
        if p.phase.gaze in ("cross", "fixate") and len(s.t):
            _cross_phase(parts, grid, s, p.fixation, p.end_s, session.in_saccade, p.phase.gaze == "cross")
        elif p.phase.gaze == "pursuit" and p.fixation.target is not None and len(s.t):
            _pursuit_phase(parts, s, p.fixation.target, p.start_s, session.velocity[sel], session.near_saccade[sel])
            parts.pursuit_s += p.phase.duration_s
            parts.n_catch += int((~session.is_fixation[ev]).sum())
    out.update(_summary(parts))
    in_trial = session.event_trial == int(row["trial"])
    out["n_fixations"] = int((in_trial & session.is_fixation).sum())
    out["n_saccades"] = int((in_trial & ~session.is_fixation).sum())
    return out


def trial_measures(grid: GazeGrid, trials: pd.DataFrame, plan: SessionPlan,
                   method: EventMethod | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(per-trial measures, events) of one session: one row per trial of ``trials`` (columns ``trial`` and
    :data:`TRIAL_MEASURES`), and the pymovements events with the trial (-1: between trials) and phase
    each began in."""
    method = method or EventMethod()
    events, velocity = detect_events(grid.t_s, grid.az_deg, grid.el_deg, grid.rate_hz, method)
    n = len(events)
    session = _SessionGaze(grid, events, velocity, *_saccade_masks(grid.t_s, events),
                           onset_s=events["onset_s"].to_numpy(dtype=np.float64),
                           is_fixation=(events["name"] == "fixation").to_numpy(dtype=bool),
                           event_trial=np.full(n, -1, dtype=np.int64), event_phase=np.full(n, "", dtype=object))
    config = loop_config(plan)
    table = pd.DataFrame([_trial_row(session, row, plan, config) for row in trials.to_dict("records")])
    events["trial"], events["phase"] = session.event_trial, session.event_phase
    for name, value in grid.flags.items():
        table[name] = value  # the session's stream faults, by name, on every row
    table["rate_hz"], table["rate_source"] = grid.rate_hz, grid.rate_source
    return table, events
