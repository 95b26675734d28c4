"""The former per-sample forms of psyop.quality's trial measures and trial-window test (boolean masks over the
whole session per trial and per phase, one mask per saccade, one mask per trial window) and of the rebuilt
stream (the simulated tracker asked phase by phase), kept outside production as the reference the span-based
and whole-run forms are held to, exactly, on the same sessions (tests/quality/test_quality_speed_equality.py)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd
import pyarrow as pa

from psyop.quality.events import EventMethod, detect_events
from tests.quality.former_trial_parts import (
    _err,
    _eye_errors,
    _pursuit_phase,
    _SessionGaze,
    _summary,
    _TrialParts,
)
from psyop.quality.resimulate import runs_of
from psyop.quality.samples import GazeGrid
from psyop.quality.target import loop_config, trial_phases
from psyop.session.gaze.plan import FixationPlan
from psyop.session.gaze.simulated import SampleBlock, SimulatedTracker
from psyop.session.log.raw_gaze import raw_gaze_block_table, raw_gaze_table
from psyop.session.loop import LoopConfig
from psyop.session.plan import SessionPlan
from psyop.session.rows import TrialRow


def _saccade_masks(t_s: np.ndarray, events: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """(in a saccade, within 2 samples of one) per sample: a velocity next to a saccade still carries part
    of it."""
    in_saccade = np.zeros(len(t_s), dtype=bool)
    for onset, offset in events.loc[events["name"] != "fixation", ["onset_s", "offset_s"]].itertuples(index=False):
        in_saccade |= (t_s >= onset) & (t_s <= offset)
    near_saccade = in_saccade.copy()
    for k in (1, 2):
        near_saccade[k:] |= in_saccade[:-k]
        near_saccade[:-k] |= in_saccade[k:]
    return in_saccade, near_saccade


def _loss_measures(grid: GazeGrid, window: np.ndarray, start_s: float, end_s: float) -> dict[str, float | int]:
    """Valid and expected sample counts, data loss share and longest gap of one trial's ``window``."""
    expected = max(1, int(round((end_s - start_s) * grid.rate_hz))) if math.isfinite(grid.rate_hz) else 0
    valid_t = grid.t_s[window & grid.valid]
    edges = np.concatenate([[start_s], valid_t, [end_s]])
    return {"n_samples_valid": int(len(valid_t)), "n_samples_expected": expected,
            "data_loss_share": max(0.0, 1.0 - len(valid_t) / expected) if expected else 1.0,
            "longest_gap_s": float(np.max(np.diff(edges)))}


@dataclass(frozen=True)
class _Samples:
    """The valid samples of one phase: ``sel`` over the grid, and their az, el (deg) and times (s)."""

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
    parts.precision.add(np.flatnonzero(s.sel)[still], s.az[still], s.el[still])


def _trial_row(session: _SessionGaze, row: TrialRow, plan: SessionPlan, config: LoopConfig) -> dict[str, object]:
    """One trial's measures; marks the events that began in it with its trial number and phase."""
    grid = session.grid
    start, end = float(row["trial_start_s"]), float(row["trial_end_s"])
    window = (grid.t_s >= start) & (grid.t_s < end)
    out: dict[str, object] = {"trial": int(row["trial"]), **_loss_measures(grid, window, start, end)}
    parts = _TrialParts()
    for p in trial_phases(plan, row, config):
        sel = window & grid.valid & (grid.t_s >= p.start_s) & (grid.t_s < p.end_s)
        ev = (session.onset_s >= p.start_s) & (session.onset_s < p.end_s)
        session.event_trial[ev], session.event_phase[ev] = int(row["trial"]), p.phase.name
        s = _Samples(sel, grid.az_deg[sel], grid.el_deg[sel], grid.t_s[sel])
        if p.phase.gaze in ("cross", "fixate") and len(s.t):
            _cross_phase(parts, grid, s, p.fixation, p.end_s, session.in_saccade, p.phase.gaze == "cross")
        elif p.phase.gaze == "pursuit" and p.fixation.target is not None and len(s.t):
            _pursuit_phase(parts, s, p.fixation.target, p.start_s, session.velocity[sel], session.near_saccade[sel])
            parts.pursuit_s += p.phase.duration_s
            parts.n_catch += int((ev & ~session.is_fixation).sum())
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


def in_trial_windows(gaze: pd.DataFrame, trials: pd.DataFrame) -> np.ndarray:
    """Which rows of ``gaze`` lie inside a trial of their own run: ``[trial_start_s, trial_end_s)``."""
    t_s = gaze["gaze_sample_t_s"].to_numpy(float)
    runs = gaze["run"].to_numpy() if "run" in gaze else np.zeros(len(gaze), dtype=np.int64)
    inside = np.zeros(len(gaze), dtype=bool)
    for run, rows in runs_of(trials):
        mine = runs == run
        for start, end in zip(rows["trial_start_s"].to_numpy(float), rows["trial_end_s"].to_numpy(float)):
            inside |= mine & (t_s >= start) & (t_s < end)
    return inside


def run_stream(tracker: SimulatedTracker, plan: SessionPlan, run: int, trials: pd.DataFrame) -> pa.Table:
    """The rebuilt stream of one run's ``trials`` phase by phase: :meth:`SimulatedTracker.samples_block` of each
    phase's ticks under the plans set so far, then :meth:`SimulatedTracker.set_plan` (one table per trial)."""
    rate = tracker.config.rate_hz
    config = loop_config(plan)
    tables = []
    for row in trials.sort_values("trial_start_s", kind="stable").to_dict("records"):
        start_s, end_s = float(row["trial_start_s"]), float(row["trial_end_s"])
        next_tick, last_tick = math.ceil(start_s * rate), math.ceil(end_s * rate) - 1
        blocks: list[SampleBlock] = []
        for phase in trial_phases(plan, row, config):
            before = min(math.ceil(phase.start_s * rate) - 1, last_tick)
            if before >= next_tick:
                blocks.append(tracker.samples_block(np.arange(next_tick, before + 1)))
                next_tick = before + 1
            tracker.set_plan(phase.fixation)
        if last_tick >= next_tick:
            blocks.append(tracker.samples_block(np.arange(next_tick, last_tick + 1)))
        tables.append(_delivered_table(blocks, tracker.config.latency_s, run, int(row["trial"])))
    return pa.concat_tables(tables) if tables else raw_gaze_table([], run=run, trial=-1)


def _delivered_table(blocks: list[SampleBlock], latency_s: float, run: int, trial: int) -> pa.Table:
    if not blocks:
        return raw_gaze_table([], run=run, trial=trial)
    t = np.concatenate([b.t_s for b in blocks])
    keep = np.concatenate([b.delivered for b in blocks])
    fixation = np.concatenate([b.fixation_m for b in blocks])[keep]
    return raw_gaze_block_table(t[keep], t[keep] + latency_s, np.concatenate([b.valid for b in blocks])[keep],
                                np.concatenate([b.confidence for b in blocks])[keep], fixation, run=run, trial=trial)
