"""The full raw stream of a simulated session that recorded only the samples it asked for.

A ``--tracker sim`` session whose protocol says ``raw_stream: requested`` (the shipped protocols' choice: an
``every_sample`` stream is about 30 times the disk) holds a few samples per trial, so precision, pursuit
gain and lag, catch-up saccades and eye-movement events cannot be measured from it. The simulated tracker is
stateless in time (:mod:`psyop.session.gaze.simulated`): the sample at tick k is a function of the tracker's
seed, its configuration and the fixation plan active at k. All three are recorded: the seed
(``seed_for(session.json seed, "tracker")``), the configuration (the recorded protocol's ``observer: eye:``
with the participant's overrides, and session.json ``sim_tracker_faults``) and the plans (each phase's
:func:`psyop.session.loop.fixation_plan` from the trial row, :func:`psyop.quality.target.trial_phases`). So
:func:`resimulate_gaze` rebuilds every tick of every trial window, in the order an ``every_sample`` session
streams them, and then checks the rebuilt stream against **every** sample the session recorded inside a trial
window: the same ticks delivered, the same validity, the fixation points within :data:`TOLERANCE_M` (the
recorded samples come from :meth:`SimulatedTracker.sample_at`, the rebuilt from
:meth:`SimulatedTracker.samples_under`, each run's ticks at once, which agree to round-off). A session that disagrees anywhere, records
no faults, or has no recorded sample to check against is not rebuilt (:attr:`Resimulation.usable` False,
:attr:`Resimulation.reason` says why) and keeps its requested-stream measures: a rebuilt stream is never used
on trust. Nothing recorded is read for anything but the check, and nothing is written.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import pandas as pd
import pyarrow as pa

from psyop.quality.target import loop_config, trial_phases
from psyop.session.gaze.plan import FixationPlan
from psyop.session.gaze.simulated import SampleBlock, SimulatedTracker, SimulatedTrackerConfig, seed_for, tracker_config
from psyop.session.log.raw_gaze import raw_gaze_block_table, raw_gaze_table
from psyop.session.log.record import SessionRecord
from psyop.session.plan import SessionPlan

#: largest difference (m, per fixation coordinate) between a recorded and a rebuilt sample; the two
#: computations differ by round-off (about 1e-16 m at 1 m), a different model or seed by centimetres
TOLERANCE_M = 1e-9


@dataclass(frozen=True)
class Resimulation:
    """The rebuilt stream (``gaze``: GAZE_SCHEMA columns, every delivered tick of every trial window, or None
    when not usable) and its check: ``n_checked`` recorded samples compared, ``n_disagreeing`` of them not
    rebuilt equal, ``max_error_m`` the largest coordinate difference of the matched ones; ``reason``: why
    it is not usable ("" when it is)."""

    gaze: pd.DataFrame | None
    n_checked: int
    n_disagreeing: int
    max_error_m: float
    reason: str

    @property
    def usable(self) -> bool:
        return self.gaze is not None


def _refused(reason: str, n_checked: int = 0, n_disagreeing: int = 0, max_error_m: float = math.nan) -> Resimulation:
    return Resimulation(None, n_checked, n_disagreeing, max_error_m, reason)


def runs_of(trials: pd.DataFrame) -> list[tuple[int, pd.DataFrame]]:
    """``trials`` split by run (column ``run``; none: all run 0), runs in order: each run's session clock
    starts at 0 (a resumed session's trial times overlap the first run's), so a run is measured apart."""
    if "run" not in trials:
        return [(0, trials)]
    return [(int(run), rows) for run, rows in trials.groupby(trials["run"].fillna(0).astype(int), sort=True)]


def rebuilt_stream(plan: SessionPlan, record: SessionRecord, participant: str, trials: pd.DataFrame) -> pa.Table:
    """Every sample the session's simulated tracker delivers inside each trial's ``[trial_start_s, trial_end_s)``,
    as an ``every_sample`` run of the same session would have recorded it (``run``/``trial`` from the row);
    each run's tracker starts afresh with the same seed, as :mod:`psyop.run.backends` builds it."""
    assert record.seed is not None and record.sim_tracker_faults is not None  # resimulate_gaze checked
    faults = record.sim_tracker_faults
    base = dataclasses.replace(SimulatedTrackerConfig(), dropout_rate_hz=faults.dropout_rate_hz,
                               nan_burst_rate_hz=faults.nan_burst_rate_hz, raw_stream="requested")
    eye = plan.observer.eye if plan.observer is not None else None
    config = tracker_config(eye, participant, base)
    tables = [_run_stream(SimulatedTracker(seed_for(record.seed, "tracker"), config), plan, run, rows)
              for run, rows in runs_of(trials)]
    return pa.concat_tables(tables) if tables else raw_gaze_table([], run=0, trial=-1)


@dataclass
class _Ticks:
    """The ticks of one run's trial windows in stream order, with the plan :meth:`SimulatedTracker.set_plan` made
    active for each (an index into ``plans``, every plan set in order after the tracker's first) and its trial:
    gathered block by block (``blocks``: first and last tick, the active plans, the trial), built at once by
    :meth:`arrays`."""

    plans: list[FixationPlan]
    active: list[int]
    blocks: list[tuple[int, int, int, int, float, int]] = dataclasses.field(default_factory=list)

    def add(self, first: int, last: int, trial: int) -> None:
        """Ticks ``first`` to ``last`` under the active plans (one, or an earlier one and the last set)."""
        earlier, latest = self.active[0], self.active[-1]
        later_s = self.plans[latest].start_s if len(self.active) > 1 else math.inf
        self.blocks.append((first, last, earlier, latest, later_s, trial))

    def set_plan(self, plan: FixationPlan) -> None:
        """:meth:`SimulatedTracker.set_plan`'s rule: the last plan begun before ``plan`` stays, then ``plan``."""
        self.active = [i for i in self.active if self.plans[i].start_s < plan.start_s][-1:] + [len(self.plans)]
        self.plans.append(plan)

    def arrays(self, rate_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(ticks, plan of each, trial of each, where each block starts): each tick under the later active plan
        from that plan's start on (``tick / rate_hz >= start_s``), else the earlier, as
        :meth:`SimulatedTracker.samples_block` picks among the plans set (their starts ascend)."""
        first, last, earlier, latest, later_s, trial = (np.array(column) for column in zip(*self.blocks))
        counts = last - first + 1
        starts = np.concatenate([[0], np.cumsum(counts)])
        ticks = np.arange(starts[-1], dtype=np.int64) + np.repeat(first - starts[:-1], counts)
        which = np.where(ticks / rate_hz >= np.repeat(later_s, counts), np.repeat(latest, counts),
                         np.repeat(earlier, counts))
        return ticks, which.astype(np.int64), np.repeat(trial, counts).astype(np.int64), starts[:-1]


def _run_ticks(plan: SessionPlan, trials: pd.DataFrame, rate_hz: float) -> _Ticks:
    """Every tick in each of ``trials``' ``[trial_start_s, trial_end_s)`` (trials in start order), each phase's
    ticks under the plans set before it, as a tracker stepped through the run phase by phase has them."""
    config = loop_config(plan)
    out = _Ticks([FixationPlan("cross", 0.0)], [0])  # a fresh tracker's plan before any is set
    for row in trials.sort_values("trial_start_s", kind="stable").to_dict("records"):
        start_s, end_s = float(row["trial_start_s"]), float(row["trial_end_s"])
        next_tick, last_tick = math.ceil(start_s * rate_hz), math.ceil(end_s * rate_hz) - 1  # ticks in [start, end)
        for phase in trial_phases(plan, row, config):  # each phase's ticks before the next plan, under the plans so far
            before = min(math.ceil(phase.start_s * rate_hz) - 1, last_tick)
            if before >= next_tick:
                out.add(next_tick, before, int(row["trial"]))
                next_tick = before + 1
            out.set_plan(phase.fixation)
        if last_tick >= next_tick:
            out.add(next_tick, last_tick, int(row["trial"]))
    return out


def _run_stream(tracker: SimulatedTracker, plan: SessionPlan, run: int, trials: pd.DataFrame) -> pa.Table:
    """:func:`rebuilt_stream` of one run's ``trials`` (its tracker given fresh): every tick at once
    (:meth:`SimulatedTracker.samples_under`), or block by block where the trial windows overlap."""
    steps = _run_ticks(plan, trials, tracker.config.rate_hz)
    if not steps.blocks:
        return raw_gaze_table([], run=run, trial=-1)
    ticks, which, trial, starts = steps.arrays(tracker.config.rate_hz)
    if np.all(np.diff(ticks) >= 0):
        blocks = [tracker.samples_under(ticks, steps.plans, which)]
    else:  # overlapping windows: each block ascends on its own
        blocks = [tracker.samples_under(t, steps.plans, w) for t, w in zip(np.split(ticks, starts[1:]),
                                                                            np.split(which, starts[1:]))]
    return _delivered_table(blocks, tracker.config.latency_s, run, trial)


def _delivered_table(blocks: list[SampleBlock], latency_s: float, run: int, trial: np.ndarray) -> pa.Table:
    """The ticks of ``blocks`` a dropout did not keep from being delivered, as an every_sample stream
    records them (:meth:`SimulatedTracker._stream_until`: received ``latency_s`` after the tick), each with
    its ``trial``."""
    t = np.concatenate([b.t_s for b in blocks])
    keep = np.concatenate([b.delivered for b in blocks])
    fixation = np.concatenate([b.fixation_m for b in blocks])[keep]
    table = raw_gaze_block_table(t[keep], t[keep] + latency_s, np.concatenate([b.valid for b in blocks])[keep],
                                 np.concatenate([b.confidence for b in blocks])[keep], fixation, run=run, trial=-1)
    column = table.schema.get_field_index("trial")
    return table.set_column(column, table.schema.field(column), pa.array(trial[keep], type=pa.int64()))


def in_trial_windows(gaze: pd.DataFrame, trials: pd.DataFrame) -> np.ndarray:
    """Which rows of ``gaze`` lie inside a trial of their own run: ``[trial_start_s, trial_end_s)``."""
    t_s = gaze["gaze_sample_t_s"].to_numpy(float)
    runs = gaze["run"].to_numpy() if "run" in gaze else np.zeros(len(gaze), dtype=np.int64)
    inside = np.zeros(len(gaze), dtype=bool)
    for run, rows in runs_of(trials):
        mine = runs == run
        start, end = rows["trial_start_s"].to_numpy(float), rows["trial_end_s"].to_numpy(float)
        some = start < end  # a window that holds a time (neither bound NaN)
        # a time is inside as many windows as there are starts at or before it less ends at or before it
        opened = np.searchsorted(np.sort(start[some]), t_s[mine], side="right")
        closed = np.searchsorted(np.sort(end[some]), t_s[mine], side="right")
        inside[mine] = opened > closed
    return inside


def _matched_rows(rebuilt: pd.DataFrame, recorded: pd.DataFrame, rate_hz: float) -> np.ndarray:
    """Per recorded row the first rebuilt row of the same run and tick (``rint(t * rate_hz)``), -1 for none."""
    def keys(frame: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
        runs = frame["run"].to_numpy() if "run" in frame else np.zeros(len(frame), dtype=np.int64)
        return runs, np.rint(frame["gaze_sample_t_s"].to_numpy(float) * rate_hz).astype(np.int64)

    (rec_run, rec_tick), (reb_run, reb_tick) = keys(recorded), keys(rebuilt)
    match = np.full(len(recorded), -1, dtype=np.int64)
    for run in np.unique(rec_run).tolist():
        rows = np.flatnonzero(reb_run == run)
        ticks, first = np.unique(reb_tick[rows], return_index=True)  # each tick's first rebuilt row
        mine = np.flatnonzero(rec_run == run)
        at = np.minimum(np.searchsorted(ticks, rec_tick[mine]), max(len(ticks) - 1, 0))
        found = ticks[at] == rec_tick[mine] if len(ticks) else np.zeros(len(mine), dtype=bool)
        match[mine[found]] = rows[first[at[found]]]
    return match


def check_against_recorded(rebuilt: pd.DataFrame, recorded: pd.DataFrame, trials: pd.DataFrame,
                           rate_hz: float) -> tuple[int, int, float]:
    """(recorded samples checked, of them not rebuilt equal, largest coordinate difference of the matched):
    every recorded sample inside a trial window of its run must be a rebuilt tick of that run with the same
    validity and its fixation point within :data:`TOLERANCE_M` (NaN where invalid on both sides)."""
    if recorded.empty:
        return 0, 0, math.nan
    recorded = recorded[np.isfinite(recorded["gaze_sample_t_s"].to_numpy(float)) & in_trial_windows(recorded, trials)]
    if recorded.empty:
        return 0, 0, math.nan
    axes = [f"fixation_{a}_m" for a in "xyz"]
    match = _matched_rows(rebuilt, recorded, rate_hz)
    found = match >= 0
    same_valid = np.zeros(len(recorded), dtype=bool)
    same_valid[found] = recorded["gaze_valid"].to_numpy()[found] == rebuilt["gaze_valid"].to_numpy()[match[found]]
    ours, theirs = recorded[axes].to_numpy(float), np.full((len(recorded), len(axes)), np.nan)
    theirs[found] = rebuilt[axes].to_numpy(float)[match[found]]
    diff = np.abs(ours - theirs)
    nan_both = np.isnan(ours) & np.isnan(theirs)
    close = np.all(nan_both | (diff <= TOLERANCE_M), axis=1)
    agree = same_valid & close
    finite = diff[found & ~np.any(nan_both, axis=1)]
    return int(len(recorded)), int((~agree).sum()), float(np.max(finite)) if finite.size else math.nan


def resimulate_gaze(plan: SessionPlan, record: SessionRecord, participant: str, trials: pd.DataFrame,
                    recorded: pd.DataFrame) -> Resimulation:
    """The rebuilt full stream of a ``--tracker sim`` session, checked against ``recorded`` (its gaze.parquet).

    Examples
    --------
    A record without the tracker's faults (a session psyop recorded before it stored them) is not rebuilt:

    >>> r = resimulate_gaze(None, SessionRecord(seed=1, tracker="sim"), "S01", pd.DataFrame(), pd.DataFrame())
    >>> r.usable, r.reason
    (False, 'session.json has no sim_tracker_faults (recorded before psyop stored them)')
    """
    if (record.tracker or "").partition(":")[0] != "sim":
        return _refused(f"not a simulated tracker ({record.tracker!r})")
    if record.seed is None:
        return _refused("session.json has no seed")
    if record.sim_tracker_faults is None:
        return _refused("session.json has no sim_tracker_faults (recorded before psyop stored them)")
    if trials.empty:
        return _refused("no trial recorded")
    rebuilt = rebuilt_stream(plan, record, participant, trials).to_pandas()
    eye = plan.observer.eye if plan.observer is not None else None
    rate = tracker_config(eye, participant).rate_hz
    n, bad, worst = check_against_recorded(rebuilt, recorded, trials, rate)
    if n == 0:
        return _refused("no recorded sample inside a trial to check the rebuilt stream against")
    if bad:
        why = ("; on a real clock a sample asked for late (after its phase's nominal start, before the loop set "
               "that phase's gaze plan) follows the earlier plan, so only a session that kept up is rebuilt"
               if record.clock == "real" else "")
        return _refused(f"{bad} of {n} recorded samples differ from the rebuilt stream (largest difference "
                        f"{worst:.3g} m; tolerance {TOLERANCE_M:g} m){why}", n, bad, worst)
    return Resimulation(rebuilt, n, 0, worst, "")
