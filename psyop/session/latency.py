"""Gaze-to-photon latency: what each frame's gaze was, how old at display, and the protocol's rules on it.

Per frame (frames.parquet, psyop.session.loop):

- ``gaze_age_at_display_s``: the display time of the frame minus the time of the gaze sample it was rendered
  with: the gaze-to-photon age. It includes the tracker's latency (a sample's time is when the eye was in
  that state; it is available only after the tracker's own latency), the wait for the next frame and the
  software path, and the display's latency as far as the display states it: a headset runtime's predicted
  display time is its prediction of when the photons leave (so its own latency is in); the headless display
  and the desktop window give the refresh slot the frame is shown in (scan-out and pixel response are not
  in: the display profile states no latency).
- ``added_latency_s``: the latency the protocol adds (``display.added_latency_ms``, a number or a factor):
  the frame is rendered with the newest sample at or before (the newest sample's time - added latency),
  taken from the raw gaze stream (:class:`psyop.session.gaze.delay.DelayedGaze`) and held, not interpolated;
  0 without.
- ``gaze_age_intrinsic_s``: the display time minus the newest sample's time (what the frame's gaze would have
  been without the added latency: the system's own latency). So ``gaze_age_at_display_s`` =
  ``gaze_age_intrinsic_s`` + ``added_latency_s`` + the age of the held sample beyond it (under one tracker
  sample period, 0 when a sample lies exactly there). Without added latency and with valid gaze the two
  ages are equal.

Per trial (trials.parquet), over the frames of its stimulus phases (the intervals) whose gaze was valid (a
held frame's age is gaze loss, which ``gaze_valid_fraction`` counts): ``gaze_age_median_s``,
``gaze_age_p95_s``, ``gaze_age_max_s`` (of ``gaze_age_at_display_s``), ``gaze_age_over_share`` (the share of
those frames whose intrinsic age exceeded the protocol's ``trial.max_gaze_age_ms``) and ``gaze_age_ok``
(that share is at most ``trial.max_gaze_age_over_share``); the last two null without a bound, all five
null when no interval frame had valid gaze (e.g. an unsampled trial on the virtual clock).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import pyarrow as pa

from psyop.records import JsonMapping, JsonObject, TrialRow
from psyop.session.phases import PhaseSpec

#: the per-trial columns (trials.parquet), in order
GAZE_AGE_COLUMNS: tuple[str, ...] = ("gaze_age_median_s", "gaze_age_p95_s", "gaze_age_max_s",
                                     "gaze_age_over_share", "gaze_age_ok")
GAZE_AGE_OK = "gaze_age_ok"
GAZE_AGE_FIELDS: tuple[pa.Field, ...] = (*(pa.field(n, pa.float64()) for n in GAZE_AGE_COLUMNS[:4]),
                                         pa.field(GAZE_AGE_OK, pa.bool_()))
#: the BIDS sidecar description of each per-trial column (psyop.export through psyop.session.timing)
GAZE_AGE_DESCRIPTIONS: dict[str, JsonObject] = {
    "gaze_age_median_s": {"Description": "median gaze-to-photon age (display time - gaze sample time) of the trial's "
                                         "interval frames with valid gaze (psyop latency)", "Units": "s"},
    "gaze_age_p95_s": {"Description": "95th percentile of the same", "Units": "s"},
    "gaze_age_max_s": {"Description": "maximum of the same", "Units": "s"},
    "gaze_age_over_share": {"Description": "share of those frames whose gaze, not counting latency the protocol added, "
                                           "was older than trial.max_gaze_age_ms (n/a: no bound)"},
    "gaze_age_ok": {"Description": "gaze_age_over_share was at most trial.max_gaze_age_over_share (n/a: no bound)"},
}
#: the phase kind (``show``) the per-trial columns are taken over
TRIAL_KIND = "stimulus"
#: what the numbers are, in one line (session.json, psyop timing)
WHAT = ("gaze_age_at_display_s: display time - time of the gaze sample the frame was rendered with (tracker latency, "
        "frame wait, software path; the display's own latency only where its display time is a predicted photon "
        "time: headset runtimes), frames with valid gaze; intrinsic: the same for the newest sample, without the "
        "latency the protocol added")


@dataclass(frozen=True)
class GazeLatency:
    """The protocol's rules on gaze latency: the latency it adds (``display.added_latency_ms``: a number, or a
    factor read per trial) and the bound it states (``trial.max_gaze_age_ms``, ``max_gaze_age_over_share``)."""

    added_ms: float = 0.0
    added_factor: str | None = None
    max_age_s: float | None = None
    max_over_share: float = 0.05

    @property
    def adds(self) -> bool:
        """Whether any trial renders with added latency."""
        return self.added_factor is not None or self.added_ms > 0.0

    def added_s(self, row: TrialRow) -> float:
        """The latency added in trial ``row``, s."""
        if self.added_factor is not None:
            return float(row[self.added_factor]) / 1000.0
        return self.added_ms / 1000.0

    def as_dict(self) -> JsonObject:
        """As session.json records it (``gaze_latency``)."""
        return {"added_latency_ms": None if self.added_factor is not None else self.added_ms,
                "added_latency_factor": self.added_factor,
                "max_gaze_age_ms": None if self.max_age_s is None else self.max_age_s * 1000.0,
                "max_gaze_age_over_share": self.max_over_share}

    @classmethod
    def of_record(cls, record: Mapping[str, object] | None) -> GazeLatency:
        """The rules session.json ``gaze_latency`` records (none: a session before it: no rules)."""
        if not record:
            return cls()
        added, bound = record.get("added_latency_ms"), record.get("max_gaze_age_ms")
        return cls(added_ms=float(str(added)) if added is not None else 0.0,
                   added_factor=None if record.get("added_latency_factor") is None
                   else str(record["added_latency_factor"]),
                   max_age_s=None if bound is None else float(str(bound)) / 1000.0,
                   max_over_share=float(str(record.get("max_gaze_age_over_share", 0.05))))


def age_stats(ages_s: np.ndarray) -> JsonObject:
    """``n_frames`` and the median, 95th percentile and maximum (s; null without a finite age) of ``ages_s``."""
    ages = np.asarray(ages_s, dtype=np.float64)
    ages = ages[np.isfinite(ages)]
    if not ages.size:
        return {"n_frames": 0, "median_s": None, "p95_s": None, "max_s": None}
    median, p95 = np.percentile(ages, [50, 95])
    return {"n_frames": int(ages.size), "median_s": float(median), "p95_s": float(p95), "max_s": float(ages.max())}


def trial_columns(age_s: np.ndarray, intrinsic_s: np.ndarray, rule: GazeLatency) -> JsonObject:
    """The five per-trial columns (module docstring) of one trial's interval frames with valid gaze."""
    age, intrinsic = np.asarray(age_s, dtype=np.float64), np.asarray(intrinsic_s, dtype=np.float64)
    keep = np.isfinite(age)
    stats = age_stats(age[keep])
    if not stats["n_frames"]:
        return dict.fromkeys(GAZE_AGE_COLUMNS)
    out: JsonObject = {"gaze_age_median_s": stats["median_s"], "gaze_age_p95_s": stats["p95_s"],
                       "gaze_age_max_s": stats["max_s"], "gaze_age_over_share": None, GAZE_AGE_OK: None}
    if rule.max_age_s is not None:
        share = float(np.mean(intrinsic[keep] > rule.max_age_s + 1e-12))
        out["gaze_age_over_share"] = share
        out[GAZE_AGE_OK] = share <= rule.max_over_share + 1e-12
    return out


@dataclass
class GazeAges:
    """One trial's frames as the latency columns need them: the timed phase each belongs to (index into the
    plan's phases; -1: the response phase), its gaze age at display, intrinsic age and whether its gaze was
    valid (psyop.session.timing.TrialTiming holds one)."""

    phase_index: list[int] = field(default_factory=list)
    age_s: list[float] = field(default_factory=list)
    intrinsic_s: list[float] = field(default_factory=list)
    valid: list[bool] = field(default_factory=list)
    added_s: float = 0.0

    def add(self, phase_index: int, age_s: float, intrinsic_s: float, valid: bool, added_s: float) -> None:
        self.phase_index.append(phase_index)
        self.age_s.append(age_s)
        self.intrinsic_s.append(intrinsic_s)
        self.valid.append(valid)
        self.added_s = added_s

    def kinds(self, phases: Sequence[PhaseSpec]) -> list[str]:
        """Each frame's phase kind (``show``; ``response`` for the response phase)."""
        return [phases[i].show if i >= 0 else "response" for i in self.phase_index]

    def columns(self, phases: Sequence[PhaseSpec], rule: GazeLatency) -> JsonObject:
        """The trial's latency columns (module docstring)."""
        rows = [k for k, (i, ok) in enumerate(zip(self.phase_index, self.valid))
                if ok and i >= 0 and phases[i].show == TRIAL_KIND]
        if not rows:
            return dict.fromkeys(GAZE_AGE_COLUMNS)
        return trial_columns(np.asarray(self.age_s)[rows], np.asarray(self.intrinsic_s)[rows], rule)


@dataclass
class SessionGazeAges:
    """The run's recorded trials' frames with valid gaze, by phase kind, and the trials over the bound: session.json
    ``summary.gaze_age``."""

    age_s: dict[str, list[np.ndarray]] = field(default_factory=dict)
    intrinsic_s: dict[str, list[np.ndarray]] = field(default_factory=dict)
    added_s: set[float] = field(default_factory=set)
    trials_over: list[int] = field(default_factory=list)

    def add(self, trial: GazeAges, phases: Sequence[PhaseSpec], number: int, ok: object) -> None:
        kinds = np.asarray(trial.kinds(phases), dtype=object)
        valid = np.asarray(trial.valid, dtype=bool)
        age, intrinsic = np.asarray(trial.age_s, dtype=np.float64), np.asarray(trial.intrinsic_s, dtype=np.float64)
        for kind in sorted(set(kinds.tolist())):
            rows = valid & (kinds == kind)
            self.age_s.setdefault(kind, []).append(age[rows])
            self.intrinsic_s.setdefault(kind, []).append(intrinsic[rows])
        if len(trial.age_s):
            self.added_s.add(round(trial.added_s, 9))
        if ok is False:
            self.trials_over.append(int(number))

    def summary(self, rule: GazeLatency) -> JsonObject:
        return gaze_age_summary({k: np.concatenate(v) for k, v in self.age_s.items()},
                                {k: np.concatenate(v) for k, v in self.intrinsic_s.items()},
                                rule, sorted(self.added_s), self.trials_over)


def gaze_age_summary(age_by_kind: Mapping[str, np.ndarray], intrinsic_by_kind: Mapping[str, np.ndarray],
                     rule: GazeLatency, added_s: Iterable[float], trials_over: Iterable[int]) -> JsonObject:
    """The ``gaze_age`` block: every frame with valid gaze, and by phase kind, the gaze age at display (and the
    intrinsic age) median / p95 / max; the interval frames over the bound; the trials marked ``gaze_age_ok``
    false."""
    kinds = sorted(age_by_kind)
    every = np.concatenate([age_by_kind[k] for k in kinds]) if kinds else np.zeros(0)
    intrinsic = np.concatenate([intrinsic_by_kind[k] for k in kinds]) if kinds else np.zeros(0)
    stimulus = intrinsic_by_kind.get(TRIAL_KIND, np.zeros(0))
    stimulus = stimulus[np.isfinite(stimulus)]
    over = None if rule.max_age_s is None else int(np.sum(stimulus > rule.max_age_s + 1e-12))
    return {"what": WHAT, **age_stats(every), "intrinsic": age_stats(intrinsic),
            "by_kind": {k: {**age_stats(age_by_kind[k]), "intrinsic": age_stats(intrinsic_by_kind[k])} for k in kinds},
            "added_latency_s": [float(a) for a in added_s], **rule.as_dict(),
            "n_interval_frames_over": over, "trials_over": [int(t) for t in trials_over]}


def _frame_kinds(frames: pd.DataFrame, phases: Sequence[PhaseSpec]) -> np.ndarray:
    """Each frame's phase kind (a phase name session.json's ``phases`` does not hold is the response phase's)."""
    kind_of = {p.name: p.show for p in phases}
    return np.asarray([kind_of.get(str(n), "response") for n in frames["phase"]], dtype=object)


def _intrinsic(frames: pd.DataFrame) -> np.ndarray:
    """``gaze_age_intrinsic_s``; a frame log before it: ``gaze_age_at_display_s`` (no latency was added then)."""
    column = "gaze_age_intrinsic_s" if "gaze_age_intrinsic_s" in frames else "gaze_age_at_display_s"
    return frames[column].to_numpy(dtype=np.float64, na_value=np.nan)


def frames_gaze_age(frames: pd.DataFrame, phases: Sequence[PhaseSpec], rule: GazeLatency) -> JsonObject:
    """:func:`gaze_age_summary` of a finalised frames.parquet (every run of the session)."""
    if not len(frames) or "gaze_age_at_display_s" not in frames:
        return gaze_age_summary({}, {}, rule, [], [])
    valid = frames["gaze_valid"].fillna(False).to_numpy(dtype=bool)
    kinds = _frame_kinds(frames, phases)
    age, intrinsic = frames["gaze_age_at_display_s"].to_numpy(dtype=np.float64, na_value=np.nan), _intrinsic(frames)
    ages = {str(k): age[valid & (kinds == k)] for k in sorted(set(kinds.tolist()))}
    intrinsics = {str(k): intrinsic[valid & (kinds == k)] for k in sorted(set(kinds.tolist()))}
    added = (sorted({round(float(a), 9) for a in frames["added_latency_s"].dropna()})
             if "added_latency_s" in frames else [])
    by_trial = trials_gaze_age(frames, phases, rule)
    over = by_trial.index[by_trial[GAZE_AGE_OK].map(lambda v: v is False)] if len(by_trial) else []
    return gaze_age_summary(ages, intrinsics, rule, added, [int(t) for t in over])


def trials_gaze_age(frames: pd.DataFrame, phases: Sequence[PhaseSpec], rule: GazeLatency) -> pd.DataFrame:
    """The per-trial columns recomputed from a frames.parquet, one row per trial that has frames (index: trial):
    what the loop wrote into trials.parquet."""
    if not len(frames):
        return pd.DataFrame(columns=list(GAZE_AGE_COLUMNS))
    kinds = _frame_kinds(frames, phases)
    keep = frames["gaze_valid"].fillna(False).to_numpy(dtype=bool) & (kinds == TRIAL_KIND)
    age = frames["gaze_age_at_display_s"].to_numpy(dtype=np.float64, na_value=np.nan)
    intrinsic = _intrinsic(frames)
    rows = {}
    trial_numbers = frames["trial"].to_numpy()
    for trial in pd.unique(trial_numbers):
        mine = keep & (trial_numbers == trial)
        rows[int(trial)] = (trial_columns(age[mine], intrinsic[mine], rule) if mine.any()
                            else dict.fromkeys(GAZE_AGE_COLUMNS))
    return pd.DataFrame.from_dict(rows, orient="index", columns=list(GAZE_AGE_COLUMNS))


def late_gaze_report(trials: pd.DataFrame, rule: GazeLatency) -> JsonObject:
    """session.json ``integrity``: the trials marked ``gaze_age_ok`` false and the bound."""
    late = [] if GAZE_AGE_OK not in trials else \
        [int(t) for t, ok in zip(trials["trial"], trials[GAZE_AGE_OK]) if ok is False or ok is np.False_]
    return {"late_gaze_trials": late,
            "max_gaze_age_ms": None if rule.max_age_s is None else rule.max_age_s * 1000.0}


def frame_gaze_ages(frames: pd.DataFrame, phases: Sequence[PhaseSpec]) -> tuple[tuple[str, float], ...]:
    """(phase kind, gaze age at display) of every frame with valid gaze and a finite age (the figure's histogram)."""
    if not len(frames) or "gaze_age_at_display_s" not in frames:
        return ()
    valid = frames["gaze_valid"].fillna(False).to_numpy(dtype=bool)
    age = frames["gaze_age_at_display_s"].to_numpy(dtype=np.float64, na_value=np.nan)
    keep = valid & np.isfinite(age)
    return tuple(zip((str(k) for k in _frame_kinds(frames, phases)[keep]), (float(a) for a in age[keep])))


def _ms(value: object) -> str:
    return "n/a" if value is None else f"{float(str(value)) * 1e3:.1f} ms"


def gaze_age_lines(summary: JsonMapping) -> list[str]:
    """The ``gaze_age`` block as ``psyop timing`` prints it (units in the words)."""
    if not summary or not summary.get("n_frames"):
        return ["gaze-to-photon age: no frame with valid gaze"] if summary else []
    s = summary
    out = [f"gaze-to-photon age (display time - gaze sample time, {s['n_frames']} frames with valid gaze): median "
           f"{_ms(s['median_s'])}, p95 {_ms(s['p95_s'])}, max {_ms(s['max_s'])}"]
    added = [float(a) for a in s.get("added_latency_s") or [] if a]
    intrinsic = s.get("intrinsic") or {}
    if added:
        out.append(f"  latency added on purpose: {', '.join(f'{a * 1e3:g}' for a in added)} ms; intrinsic age "
                   f"(newest sample) median {_ms(intrinsic.get('median_s'))}, p95 {_ms(intrinsic.get('p95_s'))}, "
                   f"max {_ms(intrinsic.get('max_s'))}")
    for kind, k in dict(s.get("by_kind") or {}).items():
        out.append(f"  {kind}: {k['n_frames']} frames, median {_ms(k['median_s'])}, p95 {_ms(k['p95_s'])}, "
                   f"max {_ms(k['max_s'])}")
    if s.get("max_gaze_age_ms") is not None:
        trials_over = list(s.get("trials_over") or [])
        out.append(f"  bound {float(str(s['max_gaze_age_ms'])):g} ms (intrinsic, interval frames): "
                   f"{s['n_interval_frames_over']} frames over it; {len(trials_over)} trials over "
                   f"{float(str(s['max_gaze_age_over_share'])):.0%} of their frames (gaze_age_ok false)"
                   + (f": {', '.join(str(t) for t in trials_over[:20])}" if trials_over else ""))
    return out
