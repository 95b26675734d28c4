"""Measured timing: per trial and phase (trials.parquet), per session (session.json ``summary.frame_timing``).

The session loop logs every frame's display time (frames.parquet ``display_time_s``) and the display
periods skipped before it (``display_missed_frames``: psyop.session.frames.FrameRequest). From them,
for every drawn timed phase ``P`` of a trial (``show`` cross, stimulus or blank; not the response
phase, whose length is the participant's):

- ``P_onset_s``, ``P_offset_s``: the display time of the phase's first and last frame (session clock);
- ``P_duration_s``: how long the phase was on the display: from its first frame's display time to the
  display time of the next frame shown (the next phase's first, or the response phase's; the last
  frame's display period when no frame follows);
- ``P_frames``: frames shown; ``P_dropped_frames``: the display periods inside the phase's nominal span
  (its start to its end: the trial's start plus the durations before it, as the loop times it) without a new
  frame. A frame shown ``m`` periods late skipped the slots ``display_time_s - k * period``, k = 1..m; each
  skipped slot counts in the phase whose span holds it (:func:`skipped_by_span`), so a stall that begins in a
  blank and ends in the next interval counts in each for the periods it covered there.

The trial's start is :attr:`TrialTiming.start_s` when the loop gives it, else the slot its first frame was
asked for (``display_time_s - missed * period``: the trial's start exactly on the headless display and the
window; a headset's runtime counts its skipped periods from the previous predicted display time, so there the
periods since the last trial fall into the first phase).

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

from psyop import datacontract as dc
from psyop.protocol.timing import TimingSection
from psyop.session.latency import GAZE_AGE_DESCRIPTIONS, GazeAges, GazeLatency, SessionGazeAges, frame_gaze_ages, frames_gaze_age, \
    gaze_age_lines
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


def phase_bounds_s(start_s: float, phases: Sequence[PhaseSpec]) -> np.ndarray:
    """The nominal starts of ``phases`` from ``start_s`` and the end of the last (s, len(phases) + 1 values)."""
    return float(start_s) + np.concatenate([[0.0], np.cumsum([float(p.duration_s) for p in phases])])


def skipped_by_span(display_time_s: Sequence[float], period_s: Sequence[float], missed: Sequence[int],
                    bounds_s: np.ndarray) -> np.ndarray:
    """Skipped display periods per span of ``bounds_s`` (:func:`phase_bounds_s`): index 0 before the first
    phase, 1..K the K phases, K + 1 after the last (the response phase). A frame shown ``m`` periods late
    skipped the slots ``display_time_s - k * period_s``, k = 1..m; a slot at a phase's end (within 1e-9 s, the
    loop's own tolerance) is the next phase's.

    Examples
    --------
    >>> skipped_by_span([0.0, 1.0], [0.1, 0.1], [0, 9], np.array([0.0, 0.55, 1.2])).tolist()
    [0, 5, 4, 0]
    """
    m = np.asarray(missed, dtype=np.int64).reshape(-1)
    out = np.zeros(len(bounds_s) + 1, dtype=np.int64)
    if not len(m) or not m.any():
        return out
    frame = np.repeat(np.arange(len(m)), m)
    k = np.arange(int(m.sum())) - np.repeat(np.cumsum(m) - m, m) + 1
    slots = np.asarray(display_time_s, dtype=np.float64)[frame] - k * np.asarray(period_s, dtype=np.float64)[frame]
    span = np.searchsorted(bounds_s, slots + 1e-9, side="right")
    return out + np.bincount(span, minlength=len(out))


@dataclass
class TrialTiming:
    """One trial's shown frames: the timed phase (index into the plan's phases; -1: the response phase)
    each belongs to, its display time, display period and skipped periods; ``start_s``: the trial's start
    (None: the slot its first frame was asked for, module docstring)."""

    phase_index: list[int] = field(default_factory=list)
    display_time_s: list[float] = field(default_factory=list)
    period_s: list[float] = field(default_factory=list)
    missed: list[int] = field(default_factory=list)
    start_s: float | None = None
    #: the frames' gaze ages (psyop.session.latency): the trial's latency columns
    gaze: GazeAges = field(default_factory=GazeAges)

    def add(self, phase_index: int, display_time_s: float, period_s: float, missed: int) -> None:
        self.phase_index.append(phase_index)
        self.display_time_s.append(display_time_s)
        self.period_s.append(period_s)
        self.missed.append(missed)

    def skipped(self, phases: Sequence[PhaseSpec]) -> np.ndarray:
        """:func:`skipped_by_span` of this trial: [before its start, each of ``phases``, the response phase]."""
        if not any(self.missed):
            return np.zeros(len(phases) + 2, dtype=np.int64)
        start = self.start_s if self.start_s is not None else \
            self.display_time_s[0] - self.missed[0] * self.period_s[0]
        return skipped_by_span(self.display_time_s, self.period_s, self.missed, phase_bounds_s(start, phases))

    def columns(self, phases: Sequence[PhaseSpec], rule: TimingSection | None, measured: bool = True) -> JsonObject:
        """The trial's measured-timing columns (module docstring); ``measured``: every frame was drawn
        (False: the sampled regime, no onset, offset or duration)."""
        first, last, count = self._by_phase()
        skipped = self.skipped(phases)
        out: JsonObject = {}
        stimulus_dropped = 0
        for i, (phase, label) in enumerate(zip(phases, phase_labels(phases))):
            if label is None:
                continue
            onset_key, offset_key, duration_key, frames_key, dropped_key = _phase_keys(label)
            n, missed = count.get(i, 0), int(skipped[i + 1])
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

    def _by_phase(self) -> tuple[dict[int, int], dict[int, int], dict[int, int]]:
        """Per phase index, in one pass over the frames: its first and last frame and frame count (a trial has
        a few frames; one list scan per phase was most of :meth:`columns`)."""
        first: dict[int, int] = {}
        last: dict[int, int] = {}
        count: dict[int, int] = {}
        for r, p in enumerate(self.phase_index):
            if p not in first:
                first[p] = r
            last[p] = r
            count[p] = count.get(p, 0) + 1
        return first, last, count

    def stimulus_dropped(self, phases: Sequence[PhaseSpec]) -> int:
        """Display periods skipped inside the trial's stimulus phases (what ``timing:`` rules on)."""
        skipped = self.skipped(phases)
        return int(sum(skipped[i + 1] for i, p in enumerate(phases) if p.show == "stimulus"))


def dropped_by_kind(skipped: np.ndarray, phases: Sequence[PhaseSpec]) -> dict[str, int]:
    """:func:`skipped_by_span` counts by phase kind (``show``; ``response`` after the last timed phase,
    ``before_trial`` before the first), kinds with none left out."""
    kinds = ["before_trial", *(p.show for p in phases), "response"]
    out: dict[str, int] = {}
    for kind, n in zip(kinds, skipped.tolist()):
        if n:
            out[kind] = out.get(kind, 0) + int(n)
    return out


@dataclass
class SessionTiming:
    """What the run's recorded trials showed: frame intervals (successive display times within a trial)
    and skipped periods by the kind of phase whose span held them, for session.json ``summary.frame_timing``."""

    refresh_period_s: float
    intervals_s: list[np.ndarray] = field(default_factory=list)
    dropped_by_kind: dict[str, int] = field(default_factory=dict)
    n_frames: int = 0
    #: the recorded trials' gaze ages by phase kind (session.json ``summary.gaze_age``, psyop.session.latency)
    gaze: SessionGazeAges = field(default_factory=SessionGazeAges)

    def add(self, trial: TrialTiming, phases: Sequence[PhaseSpec]) -> None:
        if trial.display_time_s:
            self.intervals_s.append(np.diff(np.asarray(trial.display_time_s, dtype=np.float64)))
        self.n_frames += len(trial.display_time_s)
        for i in set(trial.phase_index):  # every kind shown is listed, 0 when nothing was skipped
            self.dropped_by_kind.setdefault(phases[i].show if i >= 0 else "response", 0)
        for kind, n in dropped_by_kind(trial.skipped(phases), phases).items():
            self.dropped_by_kind[kind] = self.dropped_by_kind.get(kind, 0) + n

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


def frames_summary(frames: pd.DataFrame, phases: Sequence[PhaseSpec], refresh_period_s: float,
                   starts_s: Mapping[int, float] | None = None) -> JsonObject:
    """:func:`interval_summary` of a finalised frames.parquet (every run of the session); ``phases``: the timed
    phases (session.json ``phases``; a frame of any other name is the response phase's); ``starts_s``: trial ->
    its start (trials.parquet ``trial_start_s``; a trial without one starts at its first frame's asked slot).
    Skipped periods count by the kind of phase whose span held them (:class:`TrialTiming`)."""
    if not len(frames):
        return interval_summary(np.zeros(0), 0, {}, refresh_period_s)
    ordered = frames.sort_values(["trial", "frame"], kind="stable")
    intervals = ordered.groupby("trial", sort=False)[dc.DISPLAY_TIME_S].diff().to_numpy(dtype=np.float64)
    kind_of = {p.name: p.show for p in phases}
    dropped = dict.fromkeys(sorted({kind_of.get(str(n), "response") for n in ordered["phase"].unique()}), 0)
    missed = ordered[dc.DISPLAY_MISSED_FRAMES].fillna(0).astype(np.int64)
    for trial, rows in ordered.assign(missed=missed).groupby("trial", sort=False):
        if not rows["missed"].any():
            continue
        timing = TrialTiming(display_time_s=rows[dc.DISPLAY_TIME_S].astype(float).tolist(),
                             period_s=rows["display_period_s"].astype(float).tolist(),
                             missed=rows["missed"].astype(int).tolist(),
                             start_s=(starts_s or {}).get(int(str(trial))))
        for kind, n in dropped_by_kind(timing.skipped(phases), phases).items():
            dropped[kind] = dropped.get(kind, 0) + n
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
    #: the gaze-to-photon age of every frame with valid gaze, by phase kind (psyop.session.latency.frames_gaze_age)
    gaze_age: JsonObject = field(default_factory=dict)
    #: each such frame's gaze age at display and phase kind (the figure's histogram)
    gaze_ages_s: tuple[tuple[str, float], ...] = ()

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
        return out + gaze_age_lines(self.gaze_age)


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
    starts = ({int(t): float(s) for t, s in zip(trials["trial"], trials["trial_start_s"])}
              if "trial_start_s" in trials else {})
    summary = frames_summary(frames, phases, period_s, starts)
    ordered = frames.sort_values(["trial", "frame"], kind="stable") if len(frames) else frames
    intervals = (ordered.groupby("trial", sort=False)[dc.DISPLAY_TIME_S].diff().dropna().to_numpy(dtype=np.float64)
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
    rule = GazeLatency.of_record(meta.get("gaze_latency"))
    return TimingReport(directory, str(meta.get("clock", "?")), bool(meta.get("simulated")), summary,
                        tuple(float(v) for v in intervals), tuple(int(t) for t in trials["trial"]),
                        tuple(int(d) for d in dropped), tuple(reports), frames_gaze_age(frames, phases, rule),
                        frame_gaze_ages(frames, phases))


_DESCRIPTIONS = {"onset_s": ("display time of the phase's first frame (session clock)", "s"),
                 "offset_s": ("display time of the phase's last frame (session clock)", "s"),
                 "duration_s": ("the phase's measured duration: first frame's display time to the next frame shown", "s"),
                 "frames": ("frames shown in the phase", None),
                 "dropped_frames": ("display periods inside the phase's nominal span without a new frame", None)}


def timing_column_description(name: str, phase_names: Sequence[str]) -> JsonObject | None:
    """A sidecar description of a measured-timing column (BIDS events.json), None for any other column;
    ``phase_names``: session.json ``phases`` names (the column prefixes, repeats with ``_2`` ...)."""
    if name in GAZE_AGE_DESCRIPTIONS:
        return dict(GAZE_AGE_DESCRIPTIONS[name])
    if name == TIMING_OK:
        return {"Description": "the trial's stimulus phases dropped no more display frames than the protocol's "
                               "timing.max_dropped_frames (n/a: no timing: rule)"}
    for suffix, (text, units) in _DESCRIPTIONS.items():
        prefix = name.removesuffix(f"_{suffix}")
        if prefix != name and re.sub(r"_[0-9]+$", "", prefix) in phase_names:
            return {"Description": f"{prefix}: {text} (psyop measured timing)", **({"Units": units} if units else {})}
    return None
