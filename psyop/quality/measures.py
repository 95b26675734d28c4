"""Per-trial gaze data quality in degrees, against the target the participant was asked
to look at (rebuilt with :func:`psyop.session.loop.fixation_plan` from the trial row and the phase timing:
phase k starts at ``trial_start_s`` plus the durations before it; exact on the virtual clock, within a
frame of it on a real one).

Measures (:data:`TRIAL_MEASURES`): data loss against the nominal rate and the longest gap; accuracy
(mean and max angular error) on fixation (cross) and pursuit phases, before and after drift correction
(the trial's median error over the last 0.25 s of its first cross phase removed); precision (RMS-S2S and SD
as pymovements' ``rms_s2s`` and ``std_rms``, within each contiguous fixation segment of a fixation phase:
successive grid ticks with valid samples outside saccades; pooled over the segments: :func:`_precision`);
pursuit gain (median eye velocity along the target's over its speed, smooth samples from 0.1 s into a pursuit phase), lag (median angle between eye and target
velocity over the target velocity's turning rate) and catch-up saccades per second of pursuit.

The trials' phases are walked once (:func:`_walk_trial`: each phase's valid samples, its target, the trial's
drift offset), then each measure is computed for all trials of the session at once and each trial's statistic
taken over its own contiguous values, in its phases' order: the same numbers as measuring trial by trial.
"""

from __future__ import annotations

import math
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


def _spans(t_s: np.ndarray, starts_s: list[float], ends_s: list[float]) -> list[slice]:
    """The samples of ascending ``t_s`` in each ``[start_s, end_s)``, as slices (empty for a non-finite bound)."""
    first = np.searchsorted(t_s, starts_s, side="left").tolist()
    stop = np.searchsorted(t_s, ends_s, side="left").tolist()
    return [slice(a, b) if math.isfinite(start) and math.isfinite(end) else slice(0, 0)
            for a, b, start, end in zip(first, stop, starts_s, ends_s)]


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


def _mean_by_row(values: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """``np.mean`` of each trial's ``values[bounds[r]:bounds[r + 1]]`` (a session's values in trial order; its
    pairwise sum over its length, without the call overhead); NaN for a trial with none."""
    out = np.full(len(bounds) - 1, math.nan)
    for r in np.flatnonzero(bounds[1:] > bounds[:-1]).tolist():
        a, b = int(bounds[r]), int(bounds[r + 1])
        out[r] = float(np.add.reduce(values[a:b])) / (b - a)
    return out


def _max_by_row(values: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """The largest of each trial's ``values[bounds[r]:bounds[r + 1]]`` (NaN: none, or one is NaN)."""
    out = np.full(len(bounds) - 1, math.nan)
    some = bounds[1:] > bounds[:-1]
    if some.any():
        out[some] = np.maximum.reduceat(values, bounds[:-1][some])
    return out


def _median_by_row(values: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """``np.median`` of each trial's ``values[bounds[r]:bounds[r + 1]]``, all trials sorted at once: the middle
    value, or the mean of the two middle ones ((a + b) / 2, as np.median); NaN for a trial with none or a NaN."""
    counts = np.diff(bounds)
    row = np.repeat(np.arange(len(counts)), counts)
    ordered = values[np.lexsort((values, row))]  # each trial's values ascending, NaN last
    out = np.full(len(counts), math.nan)
    some = np.flatnonzero(counts > 0)
    upper = bounds[some] + counts[some] // 2
    lower = np.where(counts[some] % 2 == 1, upper, upper - 1)
    out[some] = (ordered[lower] + ordered[upper]) / 2
    out[np.unique(row[np.isnan(values)])] = math.nan
    return out


@dataclass
class _Phases:
    """One kind of phase (cross or pursuit) gathered over a session, trial by trial, phase by phase: each
    phase's valid samples (``sel``: grid indices, ascending), its trial's row position, its start, where the
    target was (a fixed centre, or the pursuit target at each sample, at +-1 ms: ``target_deg``), and the
    trial's drift offset (az, el, deg) when it was known by then."""

    sel: list[np.ndarray] = field(default_factory=list)
    row: list[int] = field(default_factory=list)
    start_s: list[float] = field(default_factory=list)
    centre_deg: list[tuple[float, float]] = field(default_factory=list)
    distance_m: list[float] = field(default_factory=list)
    offset_deg: list[tuple[float, float]] = field(default_factory=list)
    has_offset: list[bool] = field(default_factory=list)
    target_deg: list[np.ndarray] = field(default_factory=list)

    def add(self, sel: np.ndarray, row: int, start_s: float, fixation: FixationPlan,
            offset: tuple[float, float] | None) -> None:
        self.sel.append(sel)
        self.row.append(row)
        self.start_s.append(start_s)
        self.centre_deg.append(fixation.centre_deg)
        self.distance_m.append(fixation.distance_m)
        self.offset_deg.append(offset if offset is not None else (math.nan, math.nan))
        self.has_offset.append(offset is not None)

    def samples(self, n_rows: int) -> _PhaseSamples:
        """The gathered phases' samples, one entry per sample (phases in order)."""
        counts = np.array([len(s) for s in self.sel], dtype=np.int64)
        sel = np.concatenate(self.sel) if self.sel else np.zeros(0, dtype=np.int64)
        row = np.repeat(np.asarray(self.row, dtype=np.int64), counts)
        return _PhaseSamples(sel, row, np.repeat(np.arange(len(counts)), counts), counts,
                             np.searchsorted(row, np.arange(n_rows + 1), side="left"),
                             np.repeat(np.asarray(self.offset_deg, dtype=np.float64).reshape(-1, 2), counts, axis=0),
                             np.repeat(np.asarray(self.has_offset, dtype=bool), counts))


@dataclass(frozen=True)
class _PhaseSamples:
    """:meth:`_Phases.samples`: per sample its grid index, trial row position, phase number and drift offset
    (deg; ``corrected``: the trial had one); per phase its sample count; ``bounds``: each trial's samples are
    ``bounds[r]:bounds[r + 1]``."""

    sel: np.ndarray
    row: np.ndarray
    phase: np.ndarray
    counts: np.ndarray
    bounds: np.ndarray
    offset_deg: np.ndarray
    corrected: np.ndarray

    def corrected_bounds(self) -> np.ndarray:
        """``bounds`` of the drift-corrected samples alone."""
        return np.searchsorted(self.row[self.corrected], np.arange(len(self.bounds)), side="left")


def _errors(grid: GazeGrid, s: _PhaseSamples, taz: np.ndarray, tel: np.ndarray,
            prefix: str) -> dict[str, np.ndarray]:
    """Per trial the mean and largest angular error of its samples to the target (``taz``, ``tel`` per sample)
    and the mean after drift correction, as ``<prefix>_mean_deg``, ``_max_deg``, ``_corrected_mean_deg``."""
    az, el = grid.az_deg[s.sel], grid.el_deg[s.sel]
    err = _err(az, el, taz, tel)
    c = s.corrected
    corr = _err(az[c] - s.offset_deg[c, 0], el[c] - s.offset_deg[c, 1], taz[c], tel[c])
    return {f"{prefix}_mean_deg": _mean_by_row(err, s.bounds), f"{prefix}_max_deg": _max_by_row(err, s.bounds),
            f"{prefix}_corrected_mean_deg": _mean_by_row(corr, s.corrected_bounds())}


def _eye_errors(grid: GazeGrid, cross: _Phases, s: _PhaseSamples) -> dict[str, np.ndarray]:
    """Per trial and eye the mean angle (deg) between the eye's gaze normal and the line from its centre to the
    cross (at the plan's distance along the cross direction from the head origin); NaN for an eye the tracker
    does not give."""
    out = {}
    points = np.zeros((0, 3))
    if cross.sel:
        centres = np.asarray(cross.centre_deg, dtype=np.float64).reshape(-1, 2)
        points = np.asarray(cross.distance_m, dtype=np.float64)[:, None] * fick_direction(centres[:, 0], centres[:, 1])
    point = np.repeat(points, s.counts, axis=0)
    for eye in ("left", "right"):
        if eye not in grid.eyes:
            out[f"accuracy_fixation_{eye}_mean_deg"] = np.full(len(s.bounds) - 1, math.nan)
            continue
        az, el = grid.eyes[eye]
        to_target = point - grid.eye_centres_m[eye][s.sel]
        normal = fick_direction(az[s.sel], el[s.sel])
        ok = np.all(np.isfinite(to_target), axis=1) & np.all(np.isfinite(normal), axis=1)
        errors = np.asarray(angle_between_deg(normal[ok], to_target[ok]), dtype=np.float64)
        bounds = np.searchsorted(s.row[ok], np.arange(len(s.bounds)), side="left")
        out[f"accuracy_fixation_{eye}_mean_deg"] = _mean_by_row(errors, bounds)
    return out


def _phase_sums(values: np.ndarray, phase: np.ndarray, n_phases: int) -> list[float]:
    """``np.sum`` of each phase's ``values`` (``phase`` ascending), each over its own samples (pairwise)."""
    bounds = np.searchsorted(phase, np.arange(n_phases + 1), side="left")
    return [float(np.add.reduce(values[a:b])) for a, b in zip(bounds[:-1].tolist(), bounds[1:].tolist())]


def _precision(grid: GazeGrid, s: _PhaseSamples, in_saccade: np.ndarray, n_rows: int) -> dict[str, np.ndarray]:
    """Per trial RMS-S2S and SD (deg) over the contiguous fixation segments of its cross phases: runs of
    successive grid ticks of one phase, each with a valid sample outside a saccade. Squared steps and squared
    deviations from each segment's own mean are summed phase by phase, then over the trial's phases in order:
    sqrt(sum of squared steps / steps) and sqrt(sum of squared deviations / sum of (n - 1)); NaN with fewer
    than 2 steps."""
    still = ~in_saccade[s.sel]
    index, phase, az, el = s.sel[still], s.phase[still], grid.az_deg[s.sel][still], grid.el_deg[s.sel][still]
    n_phases = len(s.counts)
    same = (np.diff(index) == 1) & (phase[1:] == phase[:-1])  # a step within a segment
    steps_sq = (np.diff(az)[same]) ** 2 + (np.diff(el)[same]) ** 2
    step_phase = phase[1:][same]
    segment = np.cumsum(np.concatenate([[True], ~same])) - 1 if len(index) else np.zeros(0, dtype=np.int64)
    counts = np.bincount(segment)
    deviations = [(values - (np.bincount(segment, weights=values) / counts)[segment]) ** 2 for values in (az, el)]
    s2s = _phase_sums(steps_sq, step_phase, n_phases)
    n_steps = np.bincount(step_phase, minlength=n_phases).tolist()
    dev_az, dev_el = (_phase_sums(d, phase, n_phases) for d in deviations)
    rms, sd = np.full(n_rows, math.nan), np.full(n_rows, math.nan)
    phase_row = s.row[np.cumsum(s.counts) - 1].tolist() if n_phases else []
    totals: dict[int, list[float]] = {}
    for p, r in enumerate(phase_row):  # summed over the trial's phases in order
        t = totals.setdefault(r, [0.0, 0, 0.0])
        t[0] += s2s[p]
        t[1] += n_steps[p]
        t[2] += dev_az[p]
        t[2] += dev_el[p]
    for r, (s2s_sq, steps, dev_sq) in totals.items():
        if steps >= 2:
            rms[r], sd[r] = math.sqrt(s2s_sq / steps), math.sqrt(dev_sq / steps)
    return {"precision_rms_s2s_deg": rms, "precision_sd_deg": sd}


def _pursuit(session: _SessionGaze, pursuit: _Phases, s: _PhaseSamples, pursuit_s: np.ndarray,
             n_catch: np.ndarray) -> dict[str, np.ndarray]:
    """Per trial the pursuit phases' errors and, over their smooth samples (outside and 2 samples away from a
    saccade, from 0.1 s into the phase), the eye's velocity against the target's: gain (median eye velocity
    along the target's over its speed), lag (median direction difference over the median turning rate) and
    catch-up saccades per second of pursuit."""
    grid, h = session.grid, 1e-3
    target = np.concatenate(pursuit.target_deg) if pursuit.target_deg else np.zeros((0, 3, 2))
    tpos, ahead, behind = target[:, 0], target[:, 1], target[:, 2]
    out = _errors(grid, s, tpos[:, 0], tpos[:, 1], "accuracy_pursuit")
    t0 = np.repeat(np.asarray(pursuit.start_s, dtype=np.float64), s.counts)
    v_e = session.velocity[s.sel]
    v_t = (ahead - behind) / (2 * h)
    a_t = (ahead - 2 * tpos + behind) / h**2
    smooth = (~session.near_saccade[s.sel]) & np.all(np.isfinite(v_e), axis=1) & (grid.t_s[s.sel] >= t0 + 0.1)
    s_t = np.hypot(*v_t.T)
    good = smooth & (s_t > 1.0)
    bounds = np.searchsorted(s.row[good], np.arange(len(s.bounds)), side="left")
    v_e, v_t, a_t, s_t = v_e[good], v_t[good], a_t[good], s_t[good]
    # the eye's velocity along the target's (zero-mean noise does not bias it, unlike |v|)
    out["pursuit_gain"] = _median_by_row(np.sum(v_e * v_t, axis=1) / s_t**2, bounds)
    # the eye's velocity direction is the target's turned back by (turning rate x lag): lag = -angle / rate
    angle = _median_by_row(np.arctan2(v_t[:, 0] * v_e[:, 1] - v_t[:, 1] * v_e[:, 0], np.sum(v_t * v_e, axis=1)), bounds)
    rate = _median_by_row((v_t[:, 0] * a_t[:, 1] - v_t[:, 1] * a_t[:, 0]) / s_t**2, bounds)
    with np.errstate(divide="ignore", invalid="ignore"):
        out["pursuit_lag_s"] = np.where(np.isfinite(rate) & (np.abs(rate) > 0.1), -angle / rate, math.nan)
        out["catch_up_saccades_per_s"] = np.where(pursuit_s > 0, n_catch / pursuit_s, math.nan)
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


@dataclass
class _Walk:
    """What walking a session's trials phase by phase gathers (:func:`_walk_trial`): per trial its number and
    data loss (``rows``), the seconds of pursuit measured and the catch-up saccades in them; the cross and
    pursuit phases with valid samples."""

    rows: list[dict[str, float | int]] = field(default_factory=list)
    pursuit_s: list[float] = field(default_factory=list)
    n_catch: list[int] = field(default_factory=list)
    cross: _Phases = field(default_factory=_Phases)
    pursuit: _Phases = field(default_factory=_Phases)


def _walk_trial(session: _SessionGaze, walk: _Walk, row: TrialRow, plan: SessionPlan, config: LoopConfig) -> None:
    """Gather one trial's data loss and its cross and pursuit phases' valid samples into ``walk``; mark the
    events that began in each phase with the trial number and phase. The first cross phase with samples in its
    last 0.25 s gives the trial's drift offset: the median error there."""
    grid, r, trial = session.grid, len(walk.rows), int(row["trial"])
    start, end = float(row["trial_start_s"]), float(row["trial_end_s"])
    phases = list(trial_phases(plan, row, config))
    # the grid and the event onsets ascend: spans, not masks
    window, *spans = _spans(grid.t_s, [start] + [p.start_s for p in phases], [end] + [p.end_s for p in phases])
    event_spans = _spans(session.onset_s, [p.start_s for p in phases], [p.end_s for p in phases])
    walk.rows.append({"trial": trial, **_loss_measures(grid, window, start, end)})
    offset: tuple[float, float] | None = None
    pursuit_s, n_catch = 0.0, 0
    for p, phase, ev in zip(phases, spans, event_spans):
        first, last = max(window.start, phase.start), min(window.stop, phase.stop)
        sel = first + np.flatnonzero(grid.valid[first:last]) if last > first else np.zeros(0, dtype=np.int64)
        session.event_trial[ev], session.event_phase[ev] = trial, p.phase.name
        if not len(sel):
            continue
        if p.phase.gaze in ("cross", "fixate"):
            if offset is None and p.phase.gaze == "cross":  # only a drift recalibration measures the offset
                t_s, centre = grid.t_s[sel], p.fixation.centre_deg
                in_last = sel[t_s >= p.end_s - 0.25]
                offset = (float(np.median(grid.az_deg[in_last] - centre[0])),
                          float(np.median(grid.el_deg[in_last] - centre[1]))) if len(in_last) else None
            walk.cross.add(sel, r, p.start_s, p.fixation, offset)
        elif p.phase.gaze == "pursuit" and p.fixation.target is not None:
            rel_s, h = grid.t_s[sel] - p.start_s, 1e-3
            positions = target_positions_deg(p.fixation.target, np.concatenate([rel_s, rel_s + h, rel_s - h]))
            walk.pursuit.add(sel, r, p.start_s, p.fixation, offset)
            walk.pursuit.target_deg.append(positions.reshape(3, len(sel), 2).transpose(1, 0, 2))
            pursuit_s += p.phase.duration_s
            n_catch += int((~session.is_fixation[ev]).sum())
    walk.pursuit_s.append(pursuit_s)
    walk.n_catch.append(n_catch)


def _event_counts(session: _SessionGaze, trial: np.ndarray) -> dict[str, np.ndarray]:
    """Per trial number the fixations and saccades marked with it."""
    out = {}
    for name, kind in (("n_fixations", session.is_fixation), ("n_saccades", ~session.is_fixation)):
        numbers, counts = np.unique(session.event_trial[kind], return_counts=True)
        by_number = dict(zip(numbers.tolist(), counts.tolist()))
        out[name] = np.array([by_number.get(t, 0) for t in trial.tolist()], dtype=np.int64)
    return out


#: the per-trial columns in the order of the measures table (after ``trial`` and the data loss)
_COLUMN_ORDER = ("accuracy_fixation_mean_deg", "accuracy_fixation_max_deg", "accuracy_fixation_corrected_mean_deg",
                 "accuracy_pursuit_mean_deg", "accuracy_pursuit_max_deg", "accuracy_pursuit_corrected_mean_deg",
                 "accuracy_fixation_left_mean_deg", "accuracy_fixation_right_mean_deg", "precision_rms_s2s_deg",
                 "precision_sd_deg", "pursuit_gain", "pursuit_lag_s", "catch_up_saccades_per_s")


def _table(session: _SessionGaze, walk: _Walk) -> dict[str, object]:
    """The per-trial measures of a walked session by column, one vectorised pass per measure over all its
    trials: ``trial``, the data loss, :data:`_COLUMN_ORDER`, the event counts."""
    n = len(walk.rows)
    base: dict[str, object] = {name: [row[name] for row in walk.rows] for name in walk.rows[0]}
    cross, pursuit = walk.cross.samples(n), walk.pursuit.samples(n)
    centres = np.asarray(walk.cross.centre_deg, dtype=np.float64).reshape(-1, 2)
    taz, tel = (np.repeat(centres[:, k], cross.counts) for k in (0, 1))
    columns = {**_errors(session.grid, cross, taz, tel, "accuracy_fixation"),
               **_pursuit(session, walk.pursuit, pursuit, np.asarray(walk.pursuit_s, dtype=np.float64),
                          np.asarray(walk.n_catch, dtype=np.int64))}
    columns.update(_eye_errors(session.grid, walk.cross, cross))
    columns.update(_precision(session.grid, cross, session.in_saccade, n))
    base.update((name, columns[name]) for name in _COLUMN_ORDER)
    base.update(_event_counts(session, np.asarray(base["trial"], dtype=np.int64)))
    return base


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
    walk = _Walk()
    for row in trials.to_dict("records"):
        _walk_trial(session, walk, row, plan, config)
    events["trial"], events["phase"] = session.event_trial, session.event_phase
    session_columns = {**grid.flags, "rate_hz": grid.rate_hz, "rate_source": grid.rate_source}  # on every row
    if walk.rows:
        return pd.DataFrame({**_table(session, walk), **session_columns}), events
    table = pd.DataFrame([])
    for name, value in session_columns.items():
        table[name] = value
    return table, events
