"""Measured timing: per trial and phase (trials.parquet), per session (session.json ``summary.frame_timing``).

The session loop logs every frame's display time (frames.parquet ``display_time_s``) and the display
periods skipped before it (``display_missed_frames``: psyop.session.frames.FrameRequest). From them,
for every drawn timed phase ``P`` of a trial (``show`` cross, stimulus or blank; not the response
phase, whose length is the participant's):

- ``P_onset_s``, ``P_offset_s``: the display time of the phase's first and last frame (session clock);
- ``P_duration_s``: how long the phase was on the display: from its first frame's display time to the
  display time of the next frame shown (the next phase's first, or the response phase's; the last
  frame's display period when no frame follows);
- ``P_frames``: frames shown; ``P_dropped_frames``: display periods skipped before them (a frame drawn
  late counts the periods it skipped in the phase it belongs to).

A phase with no frame (a frame so late that the whole phase passed) has null onset, offset and duration
and 0 frames. The sampled regime of a simulated session (a virtual clock and an observer that needs no
images: one frame in the middle of a few trials' phases, docs/sessions.md) shows no phase whole: onset,
offset and duration are null there too, and ``P_frames`` counts the frames drawn. Two timed phases with the same name
(two ``blank`` phases) get ``blank`` and ``blank_2`` columns, in trial order.

``timing_ok``: whether the trial's stimulus phases dropped no more than the protocol's
``timing.max_dropped_frames`` (null: the protocol states no ``timing:`` rule; psyop.protocol.timing).
"""

from __future__ import annotations

import functools
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import pyarrow as pa

from psyop.protocol.timing import TimingSection
from psyop.session.phases import PhaseSpec
from psyop.session.rows import JsonObject

#: the per-phase columns, suffix -> arrow type
PHASE_COLUMNS: tuple[tuple[str, pa.DataType], ...] = (
    ("onset_s", pa.float64()), ("offset_s", pa.float64()), ("duration_s", pa.float64()),
    ("frames", pa.int64()), ("dropped_frames", pa.int64()))
TIMING_OK = "timing_ok"


def phase_labels(phases: Sequence[PhaseSpec]) -> list[str | None]:
    """The column prefix of each timed phase (None: it draws nothing): its name, ``_2``, ``_3`` ... for repeats."""
    seen: dict[str, int] = {}
    labels: list[str | None] = []
    for phase in phases:
        if not phase.renders:
            labels.append(None)
            continue
        seen[phase.name] = seen.get(phase.name, 0) + 1
        labels.append(phase.name if seen[phase.name] == 1 else f"{phase.name}_{seen[phase.name]}")
    return labels


def timing_column_names(phases: Sequence[PhaseSpec]) -> list[str]:
    """Every measured-timing column of trials.parquet for these phases, ``timing_ok`` last."""
    return [f"{label}_{suffix}" for label in phase_labels(phases) if label is not None
            for suffix, _ in PHASE_COLUMNS] + [TIMING_OK]


def timing_fields(phases: Sequence[PhaseSpec]) -> list[pa.Field]:
    """The arrow fields of :func:`timing_column_names`."""
    types = dict(PHASE_COLUMNS)
    fields = [pa.field(name, types[name.removeprefix(f"{label}_")])
              for label in phase_labels(phases) if label is not None
              for name in (f"{label}_{suffix}" for suffix, _ in PHASE_COLUMNS)]
    return fields + [pa.field(TIMING_OK, pa.bool_())]


@functools.lru_cache(maxsize=256)
def _phase_keys(label: str) -> tuple[str, ...]:
    """The five per-phase column names of ``label``, in :data:`PHASE_COLUMNS` order."""
    return tuple(f"{label}_{suffix}" for suffix, _ in PHASE_COLUMNS)


@dataclass
class TrialTiming:
    """One trial's shown frames: the timed phase (index into the plan's phases; -1: the response phase)
    each belongs to, its display time, display period and skipped periods."""

    phase_index: list[int] = field(default_factory=list)
    display_time_s: list[float] = field(default_factory=list)
    period_s: list[float] = field(default_factory=list)
    missed: list[int] = field(default_factory=list)

    def add(self, phase_index: int, display_time_s: float, period_s: float, missed: int) -> None:
        self.phase_index.append(phase_index)
        self.display_time_s.append(display_time_s)
        self.period_s.append(period_s)
        self.missed.append(missed)

    def columns(self, phases: Sequence[PhaseSpec], rule: TimingSection | None, measured: bool = True) -> JsonObject:
        """The trial's measured-timing columns (module docstring); ``measured``: every frame was drawn
        (False: the sampled regime, no onset, offset or duration)."""
        first, last, count, dropped = self._by_phase()
        out: JsonObject = {}
        stimulus_dropped = 0
        for i, (phase, label) in enumerate(zip(phases, phase_labels(phases))):
            if label is None:
                continue
            onset_key, offset_key, duration_key, frames_key, dropped_key = _phase_keys(label)
            n, missed = count.get(i, 0), dropped.get(i, 0)
            if n and measured:
                end = last[i]
                onset, offset = self.display_time_s[first[i]], self.display_time_s[end]
                until = (self.display_time_s[end + 1] if end + 1 < len(self.display_time_s)
                         else offset + self.period_s[end])  # the next frame shown replaces the phase's last
                out[onset_key], out[offset_key], out[duration_key] = onset, offset, until - onset
            else:
                out[onset_key] = out[offset_key] = out[duration_key] = None
            out[frames_key], out[dropped_key] = n, missed
            stimulus_dropped += missed if phase.show == "stimulus" else 0
        out[TIMING_OK] = None if rule is None else not rule.violated(stimulus_dropped)
        return out

    def _by_phase(self) -> tuple[dict[int, int], dict[int, int], dict[int, int], dict[int, int]]:
        """Per phase index, in one pass over the frames: its first and last frame, frame count and skipped
        periods (a trial has a few frames; one list scan per phase was most of :meth:`columns`)."""
        first: dict[int, int] = {}
        last: dict[int, int] = {}
        count: dict[int, int] = {}
        dropped: dict[int, int] = {}
        for r, (p, missed) in enumerate(zip(self.phase_index, self.missed)):
            if p not in first:
                first[p] = r
            last[p] = r
            count[p] = count.get(p, 0) + 1
            dropped[p] = dropped.get(p, 0) + int(missed)
        return first, last, count, dropped

    def stimulus_dropped(self, phases: Sequence[PhaseSpec]) -> int:
        """Display periods skipped over the trial's stimulus phases (what ``timing:`` rules on)."""
        return int(sum(m for i, m in zip(self.phase_index, self.missed) if i >= 0 and phases[i].show == "stimulus"))


@dataclass
class SessionTiming:
    """What the run's recorded trials showed: frame intervals (successive display times within a trial)
    and skipped periods by phase kind, for session.json ``summary.frame_timing``."""

    refresh_period_s: float
    intervals_s: list[np.ndarray] = field(default_factory=list)
    dropped_by_kind: dict[str, int] = field(default_factory=dict)
    n_frames: int = 0

    def add(self, trial: TrialTiming, phases: Sequence[PhaseSpec]) -> None:
        if trial.display_time_s:
            self.intervals_s.append(np.diff(np.asarray(trial.display_time_s, dtype=np.float64)))
        self.n_frames += len(trial.display_time_s)
        for i, missed in zip(trial.phase_index, trial.missed):
            kind = phases[i].show if i >= 0 else "response"
            self.dropped_by_kind[kind] = self.dropped_by_kind.get(kind, 0) + int(missed)

    def summary(self) -> JsonObject:
        intervals = np.concatenate(self.intervals_s) if self.intervals_s else np.zeros(0)
        return interval_summary(intervals, self.n_frames, self.dropped_by_kind, self.refresh_period_s)


def interval_summary(intervals_s: np.ndarray, n_frames: int, dropped_by_kind: Mapping[str, int],
                     refresh_period_s: float) -> JsonObject:
    """The ``frame_timing`` block: frame count, interval median / p99 / max (s; null without two frames
    in a trial), dropped frames in total and per phase kind (cross, stimulus, blank, response)."""
    finite = intervals_s[np.isfinite(intervals_s)]
    stats = ({"frame_interval_median_s": float(np.median(finite)),
              "frame_interval_p99_s": float(np.percentile(finite, 99)), "frame_interval_max_s": float(finite.max())}
             if finite.size else {"frame_interval_median_s": None, "frame_interval_p99_s": None,
                                  "frame_interval_max_s": None})
    return {"refresh_period_s": refresh_period_s, "n_frames": int(n_frames), **stats,
            "dropped_frames": int(sum(dropped_by_kind.values())),
            "dropped_frames_by_kind": {k: int(v) for k, v in sorted(dropped_by_kind.items())}}


def frames_summary(frames: pd.DataFrame, phase_kinds: Mapping[str, str], refresh_period_s: float) -> JsonObject:
    """:func:`interval_summary` of a finalised frames.parquet (every run of the session); ``phase_kinds``:
    phase name -> ``show`` (session.json ``phases``; any other name is the response phase)."""
    if not len(frames):
        return interval_summary(np.zeros(0), 0, {}, refresh_period_s)
    ordered = frames.sort_values(["trial", "frame"], kind="stable")
    intervals = ordered.groupby("trial", sort=False)["display_time_s"].diff().to_numpy(dtype=np.float64)
    kinds = ordered["phase"].map(lambda name: phase_kinds.get(str(name), "response"))
    missed = ordered["display_missed_frames"].fillna(0).astype(np.int64)
    dropped = {str(k): int(v) for k, v in missed.groupby(kinds.to_numpy()).sum().items()}
    return interval_summary(intervals, len(ordered), dropped, refresh_period_s)


def with_timing_fields(schema: pa.Schema, phases: Sequence[PhaseSpec]) -> pa.Schema:
    """The trial log's schema with the measured-timing columns of ``phases`` appended.

    Raises
    ------
    ValueError
        when a schedule column already has one of their names (a factor named like ``interval1_frames``).
    """
    taken = sorted(set(schema.names) & set(timing_column_names(phases)))
    if taken:
        raise ValueError(f"schedule column(s) {', '.join(taken)} clash with the measured-timing columns of the "
                         "trial log (docs/sessions.md \"Timing\"): rename the factor(s)")
    return pa.schema([*schema, *timing_fields(phases)])


@dataclass(frozen=True)
class PhaseReport:
    """One timed phase over a session's trials: nominal duration, measured durations and dropped frames."""

    label: str
    kind: str
    nominal_s: float
    measured_s: tuple[float, ...]  # one per trial that showed the phase (trial order)
    dropped_frames: int


@dataclass(frozen=True)
class TimingReport:
    """What ``psyop timing`` prints and draws for one finalised session (psyop.cli.timing)."""

    session: str
    clock: str
    simulated: bool
    summary: JsonObject  # :func:`frames_summary` of every run's frames
    intervals_s: tuple[float, ...]  # successive display times within a trial
    trials: tuple[int, ...]
    dropped_per_trial: tuple[int, ...]  # over every timed phase of the trial
    phases: tuple[PhaseReport, ...]

    def lines(self) -> list[str]:
        """The summary, one line each (units in the words)."""
        s = self.summary
        ms = {k: (f"{float(v) * 1e3:.2f} ms" if v is not None else "n/a") for k, v in s.items() if k.endswith("_s")}
        kinds = ", ".join(f"{k} {v}" for k, v in dict(s["dropped_frames_by_kind"]).items()) or "none"
        out = [f"{self.clock} clock{', simulated' if self.simulated else ''}: {s['n_frames']} frames; refresh period "
               f"{ms['refresh_period_s']}; frame interval median {ms['frame_interval_median_s']}, p99 "
               f"{ms['frame_interval_p99_s']}, max {ms['frame_interval_max_s']}",
               f"dropped frames: {s['dropped_frames']} ({kinds}); trials with any: "
               f"{sum(d > 0 for d in self.dropped_per_trial)} of {len(self.trials)}"]
        for p in self.phases:
            got = np.asarray(p.measured_s, dtype=np.float64)
            measured = (f"measured median {np.median(got) * 1e3:.1f} ms (min {got.min() * 1e3:.1f}, max "
                        f"{got.max() * 1e3:.1f}) over {got.size} trials" if got.size else "not measured (no frames)")
            out.append(f"{p.label} ({p.kind}): nominal {p.nominal_s * 1e3:.1f} ms, {measured}; "
                       f"{p.dropped_frames} dropped frames")
        return out


def _recorded_phase(p: Mapping[str, object]) -> PhaseSpec:
    """A timed phase as session.json ``phases`` records it (psyop.session.plan.SessionPlan.metadata)."""
    primitives = p.get("primitives")
    return PhaseSpec(str(p["name"]), float(str(p["duration_s"])), str(p["show"]), str(p.get("gaze", "none")),
                     mode_column=None if p.get("mode_column") is None else str(p["mode_column"]),
                     mode=str(p.get("mode", "conventional")),
                     primitives=tuple(str(x) for x in primitives) if isinstance(primitives, list) else None,
                     interval=int(str(p.get("interval", 0))), target_size_deg=float(str(p.get("target_size_deg", 1.0))))


def session_report(directory: str, meta: JsonObject, trials: pd.DataFrame, frames: pd.DataFrame) -> TimingReport:
    """The :class:`TimingReport` of a finalised session (its session.json, trials.parquet and frames.parquet)."""
    phases = [_recorded_phase(p) for p in meta.get("phases") or []]
    display = meta.get("display") or {}
    period_s = 1.0 / float(display["refresh_hz"]) if display.get("refresh_hz") else float("nan")
    summary = frames_summary(frames, {p.name: p.show for p in phases}, period_s)
    ordered = frames.sort_values(["trial", "frame"], kind="stable") if len(frames) else frames
    intervals = (ordered.groupby("trial", sort=False)["display_time_s"].diff().dropna().to_numpy(dtype=np.float64)
                 if len(ordered) else np.zeros(0))
    trials = trials.sort_values("trial")
    reports, dropped = [], np.zeros(len(trials), dtype=np.int64)
    for phase, label in zip(phases, phase_labels(phases)):
        if label is None or f"{label}_dropped_frames" not in trials:
            continue
        counts = trials[f"{label}_dropped_frames"].fillna(0).astype(np.int64).to_numpy()
        dropped += counts
        measured = trials[f"{label}_duration_s"].dropna().astype(float)
        reports.append(PhaseReport(label, phase.show, phase.duration_s, tuple(measured), int(counts.sum())))
    return TimingReport(directory, str(meta.get("clock", "?")), bool(meta.get("simulated")), summary,
                        tuple(float(v) for v in intervals), tuple(int(t) for t in trials["trial"]),
                        tuple(int(d) for d in dropped), tuple(reports))


_DESCRIPTIONS = {"onset_s": ("display time of the phase's first frame (session clock)", "s"),
                 "offset_s": ("display time of the phase's last frame (session clock)", "s"),
                 "duration_s": ("the phase's measured duration: first frame's display time to the next frame shown", "s"),
                 "frames": ("frames shown in the phase", None),
                 "dropped_frames": ("display periods skipped before the phase's frames", None)}


def timing_column_description(name: str, phase_names: Sequence[str]) -> JsonObject | None:
    """A sidecar description of a measured-timing column (BIDS events.json), None for any other column;
    ``phase_names``: session.json ``phases`` names (the column prefixes, repeats with ``_2`` ...)."""
    if name == TIMING_OK:
        return {"Description": "the trial's stimulus phases dropped no more display frames than the protocol's "
                               "timing.max_dropped_frames (n/a: no timing: rule)"}
    for suffix, (text, units) in _DESCRIPTIONS.items():
        prefix = name.removesuffix(f"_{suffix}")
        if prefix != name and re.sub(r"_[0-9]+$", "", prefix) in phase_names:
            return {"Description": f"{prefix}: {text} (psyop measured timing)", **({"Units": units} if units else {})}
    return None
