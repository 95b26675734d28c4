"""The gaze quality of one finalised session directory (verified first, never changed)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import pandas as pd

from psyop import datacontract as dc
from psyop.errors import UserError
from psyop.finalised import verify_session
from psyop.quality.cache import QualityCache
from psyop.quality.measures import trial_measures
from psyop.protocol.validation import VALIDATION_MEASURES
from psyop.quality.resimulate import resimulate_gaze, runs_of
from psyop.quality.samples import gaze_grid
from psyop.session.log.record import SessionRecord, read_record_file
from psyop.quality.validation import read_validations, trial_validation_measures

if TYPE_CHECKING:
    from psyop.session.plan import SessionPlan


def recorded_protocol(record: SessionRecord, meta_path: Path):
    """The protocol a session recorded (session.json ``protocol_text``), its files (a mesh) resolved beside
    the protocol file it was run from (``protocol_file``), as the session resolved them."""
    from psyop.protocol import parse_protocol

    source = record.protocol_file
    base_dir = Path(source).parent if source and Path(source).parent.is_dir() else None
    if record.protocol_text is None:
        raise UserError("session.json records no protocol_text: the session's protocol is unknown", str(meta_path))
    return parse_protocol(record.protocol_text, f"{meta_path} (protocol_text)", base_dir=base_dir)


def recorded_plan(directory: Path) -> SessionPlan:
    """The compiled plan of the protocol the finalised session in ``directory`` recorded
    (:func:`recorded_protocol`); the session is read as it is (verify it first)."""
    from psyop.session.plan import compile_plan

    meta_path = Path(directory) / dc.SESSION_METADATA_FILE
    record = read_record_file(meta_path)
    if record is None:
        raise UserError("no session.json: not a finalised psyop session", str(directory))
    return compile_plan(recorded_protocol(record, meta_path))


@dataclass(frozen=True)
class SessionGaze:
    """One finalised session's gaze as the quality analysis measures it: ``gaze`` (GAZE_SCHEMA columns) is
    the recorded raw stream, or for a ``requested`` simulated session the stream rebuilt from its seed when
    that agrees with every recorded sample (:mod:`psyop.quality.resimulate`); ``stream`` says which
    (``every_sample``, ``resimulated`` or ``requested``), ``note`` how it was checked or why it was not
    rebuilt; ``rate_hz``: the simulated tracker's nominal rate (None: from the samples)."""

    plan: SessionPlan
    trials: pd.DataFrame
    gaze: pd.DataFrame
    stream: str
    note: str
    rate_hz: float | None
    participant: str
    session: int


#: compiled plans by the recorded (protocol text, protocol file): a study's sessions share one (a mesh
#: protocol's models are parsed once, not per session); the caller owns it
PlanCache = dict[tuple[object, object], "SessionPlan"]


def cached_plan(record: SessionRecord, meta_path: Path, plans: PlanCache) -> SessionPlan:
    """The compiled plan of the protocol session.json (``record``) recorded, from ``plans`` when a session of the
    same protocol text and file was compiled before (then added)."""
    from psyop.session.plan import compile_plan

    key = (record.protocol_text, record.protocol_file)
    if key not in plans:
        plans[key] = compile_plan(recorded_protocol(record, meta_path))
    return plans[key]


def first_trials(trials: pd.DataFrame, n_trials: int) -> pd.DataFrame:
    """The trials of the first run that start before the first ``n_trials`` of its rows end: what a figure of
    those trials shows. They are the first trials in start order, which the rebuilt stream steps through in
    order (:func:`psyop.quality.resimulate.rebuilt_stream`), so their rebuilt samples are those of the whole
    session's rebuild, exactly."""
    rows = (runs_of(trials) or [(0, trials)])[0][1]
    if rows.empty:
        return rows
    end_s = float(rows["trial_end_s"].head(n_trials).max())
    return rows[rows["trial_start_s"].to_numpy(float) <= end_s]


def session_gaze(directory: Path, plans: PlanCache | None = None, n_trials: int | None = None) -> SessionGaze:
    """The verified session in ``directory`` and the gaze stream its quality is measured from; ``plans``:
    the compiled plans of sessions measured before (filled in); ``n_trials``: only the :func:`first_trials`
    (a requested stream rebuilt and checked over those alone)."""
    directory = Path(directory)
    meta_path = directory / dc.SESSION_METADATA_FILE
    if not meta_path.is_file() or not (directory / dc.TRIALS_FILE).is_file():
        raise UserError("not a finalised psyop session (no session.json and trials.parquet)", str(directory))
    verify_session(directory)
    record = read_record_file(meta_path)
    if record is None:  # removed after the check above
        raise UserError("not a finalised psyop session (no session.json)", str(directory))
    plan = cached_plan(record, meta_path, {} if plans is None else plans)
    gaze_path = directory / dc.GAZE_FILE
    gaze = pd.read_parquet(gaze_path) if gaze_path.is_file() else pd.DataFrame()
    trials = pd.read_parquet(directory / dc.TRIALS_FILE)
    return stream_of(plan, record, trials if n_trials is None else first_trials(trials, n_trials), gaze)


def stream_of(plan: SessionPlan, record: SessionRecord, trials: pd.DataFrame, recorded: pd.DataFrame) -> SessionGaze:
    """The stream a session's quality is measured from, given its plan, session.json, trials and recorded raw
    gaze (from the finalised files, or a replication's in-memory log: psyop.power.memory_log)."""
    from psyop.session.gaze.simulated import tracker_config

    participant = record.participant or ""
    rate, stream, note, gaze = None, "every_sample", "", recorded
    if (record.tracker or "").partition(":")[0] == "sim":
        config = tracker_config(plan.observer.eye if plan.observer is not None else None, participant)
        rate, stream = config.rate_hz, config.raw_stream or "requested"
    if stream == "requested":
        rebuilt = resimulate_gaze(plan, record, participant, trials, recorded)
        if rebuilt.gaze is not None:
            gaze, stream = rebuilt.gaze, "resimulated"
            note = f"rebuilt from the seed; equal to all {rebuilt.n_checked} recorded samples in trials"
        else:
            note = f"not rebuilt: {rebuilt.reason}"
    return SessionGaze(plan, trials, gaze, stream, note, rate, participant,
                       record.session if record.session is not None else 1)


def stream_measures(s: SessionGaze) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(per-trial measures, events) of ``s`` with columns ``raw_stream`` and ``raw_stream_note`` (a stream of
    the requested samples only: :func:`requested_stream_measures`, no events). Each run is measured apart
    (its session clock starts at 0: a resumed session's times overlap its first run's); rows in the order
    of ``s.trials``, events run by run."""
    tables, event_tables = [], []
    for run, trials in runs_of(s.trials) or [(0, s.trials)]:  # (no trial recorded: one empty table)
        gaze = s.gaze[s.gaze["run"].to_numpy() == run] if "run" in s.gaze else s.gaze
        measures, events = trial_measures(gaze_grid(gaze, s.rate_hz), trials, s.plan)
        if s.stream == "requested":
            measures, events = requested_stream_measures(measures, gaze), events.iloc[0:0]
        tables.append(measures.set_axis(trials.index))
        event_tables.append(events)
    measures = pd.concat(tables).loc[s.trials.index].reset_index(drop=True) if len(tables) > 1 else \
        tables[0].reset_index(drop=True)
    events = pd.concat(event_tables, ignore_index=True) if len(event_tables) > 1 else event_tables[0]
    measures.insert(1, "raw_stream", s.stream)
    measures.insert(2, "raw_stream_note", s.note)
    return measures, events


def measure_session(directory: Path, plans: PlanCache | None = None,
                    cache: QualityCache | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(per-trial measures, events) of the session in ``directory``, each with participant and session;
    from ``cache`` when it holds this session's files measured by this psyop (:mod:`psyop.quality.cache`),
    else measured (:func:`measured_session`) and stored there.

    The nominal rate is the simulated tracker's ``rate_hz`` (protocol ``observer: eye:``, default 120 Hz)
    for a simulated session, else the median interval between samples. A simulated session whose raw stream
    is ``requested`` (the shipped protocols' choice) holds only the samples the session asked for (about one
    per trial on the virtual clock); it is measured from its rebuilt full stream (:func:`session_gaze`,
    ``raw_stream`` = ``resimulated``), or where that cannot be rebuilt and checked from the samples it holds
    (:func:`requested_stream_measures`, ``raw_stream`` = ``requested``). Column ``raw_stream`` says which
    stream each row was measured from, ``raw_stream_note`` how a rebuilt one was checked or why it was not.
    ``plans``: as :func:`session_gaze`'s."""
    if cache is None:
        return measured_session(directory, plans)
    key = cache.key(Path(directory))
    kept = cache.get(key)
    if kept is not None:
        return kept
    measures, events = measured_session(directory, plans)
    cache.put(key, measures, events)
    return measures, events


def measured_session(directory: Path, plans: PlanCache | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """:func:`measure_session` without a cache: the session verified, its stream rebuilt and measured."""
    s = session_gaze(directory, plans)
    measures, events = stream_measures(s)
    validation = trial_validation_measures(s.trials, read_validations(Path(directory)))  # NaN: no gaze_validation
    for name in VALIDATION_MEASURES:
        measures[name] = validation[name].to_numpy()
    for table in (measures, events):
        table.insert(0, "session", s.session)
        table.insert(0, "participant", s.participant)
    return measures, events


#: measures a stream of the requested samples cannot give (they need the tracker's every sample)
NEEDS_EVERY_SAMPLE = ("longest_gap_s", "precision_rms_s2s_deg", "precision_sd_deg", "pursuit_gain", "pursuit_lag_s",
                      "catch_up_saccades_per_s", "n_fixations", "n_saccades")


def requested_stream_measures(measures: pd.DataFrame, gaze: pd.DataFrame) -> pd.DataFrame:
    """``measures`` of a requested-samples stream: data loss is the share of the trial's requested samples
    that were invalid (NaN for a trial that requested none; not against the nominal rate, which such a stream never meets), accuracy comes from
    the valid ones, and :data:`NEEDS_EVERY_SAMPLE` are NaN (not measurable: no silent numbers)."""
    out = measures.copy()
    if "trial" not in out:  # no trial recorded (e.g. a session its gaze validation stopped before the first)
        return out
    by_trial = gaze.groupby("trial")["gaze_valid"] if not gaze.empty else None
    requested = out["trial"].map(by_trial.size() if by_trial is not None else {}).fillna(0).astype(int)
    valid = out["trial"].map(by_trial.sum() if by_trial is not None else {}).fillna(0).astype(int)
    out["n_samples_expected"], out["n_samples_valid"] = requested, valid
    out["data_loss_share"] = 1.0 - valid / requested.where(requested > 0)  # NaN: the trial requested none
    for name in NEEDS_EVERY_SAMPLE:
        out[name] = float("nan")
    return out


def summary_lines(measures: pd.DataFrame) -> list[str]:
    """A methods-section summary of per-trial measures (medians over trials, per participant/session)."""
    lines = []
    for (participant, session), rows in measures.groupby(["participant", "session"], sort=True):
        m = rows.median(numeric_only=True)
        lines.append(
            f"sub-{participant} ses-{session}: {len(rows)} trials; data loss {100 * rows['data_loss_share'].mean():.1f} % "
            f"(longest gap {rows['longest_gap_s'].max():.3f} s); accuracy on the fixation targets {m['accuracy_fixation_mean_deg']:.2f} deg "
            f"({m['accuracy_fixation_corrected_mean_deg']:.2f} deg after drift correction); precision RMS-S2S "
            f"{m['precision_rms_s2s_deg']:.3f} deg, SD {m['precision_sd_deg']:.3f} deg; pursuit gain {m['pursuit_gain']:.2f}, "
            f"lag {1000 * m['pursuit_lag_s']:.0f} ms, {rows['catch_up_saccades_per_s'].mean():.2f} catch-up saccades/s "
            "(medians over trials; nan: no such phase)")
        if "raw_stream" in rows and rows["raw_stream"].iloc[0] != "every_sample":  # how the stream was measured
            note = str(rows["raw_stream_note"].iloc[0]) if "raw_stream_note" in rows else ""
            lines.append(f"  raw stream: {rows['raw_stream'].iloc[0]}" + (f" ({note})" if note else ""))
        flagged = {k: int(rows[k].iloc[0]) for k in ("n_non_finite_time", "n_duplicate_timestamps", "n_non_monotonic",
                                                      "n_off_grid") if int(rows[k].iloc[0])}
        if flagged:
            lines.append(f"  raw stream faults: {flagged}")
    return lines
