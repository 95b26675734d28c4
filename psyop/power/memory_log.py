"""The in-memory session log of a power replication, and the analysis table built from it.

A replication's sessions are throwaway: nobody resumes, recovers or reads them after the
analysis. :class:`MemoryLog` is what ``run_session`` records into for them (its
``store_factory``): each trial row, converted with the session's own trial schema exactly as the
durable :class:`~psyop.session.log.store.SessionStore` converts it, is kept in memory; frames are
never kept, raw gaze samples and gaze validations only for a protocol with ``quality:`` rules
(``keep_gaze``: the rules' measures read them; otherwise the loop does not even build them,
``keeps_samples`` false; a validation's attempts are kept in the log, never in a file), and
nothing is written, fsynced or locked. :func:`analysis_trials` then hands the sessions' tables to
the analysis as :func:`psyop.statistics.dataset.load_dataset` would have read them back from their
trials.parquet files (same order, same types, practice and timed-out trials left out, and what the
protocol's ``quality:`` rules exclude left out, measured from the same raw gaze as
psyop.quality.session.measure_session measures a finalised session).
``tests/power/test_memory_log.py`` holds the two to the same frame, column by column, and the
whole power table byte for byte, for every shipped study and a protocol whose rules exclude trials.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pandas as pd
import pyarrow as pa

from psyop import datacontract as dc
from psyop.session.log.layout import SessionPaths
from psyop.session.log.schema import GAZE_SCHEMA
from psyop.session.log.validation_log import VALIDATION_SCHEMA
from psyop.records import JsonMapping, JsonObject

if TYPE_CHECKING:
    from psyop.protocol.quality import QualitySection
    from psyop.session.plan import SessionPlan


class MemoryLog:
    """A session log held in memory (see the module docstring); :attr:`trials` (and :attr:`gaze`, the raw
    gaze stream as gaze.parquet would hold it, with ``keep_gaze``) after finalise."""

    def __init__(self, paths: SessionPaths, trial_schema: pa.Schema, keep_gaze: bool = False) -> None:
        self.paths = paths
        self.trial_schema = trial_schema
        self._names = tuple(trial_schema.names)  # the schema's column names, once (Schema.names builds a list)
        self.keeps_samples = keep_gaze  # the loop builds a trial's raw gaze table only for a log that keeps it
        self.run_index = 0
        self.metadata: JsonObject = {}
        self._rows: list[tuple[object, ...]] = []  # each trial's values in schema order (None: not in the row)
        self._gaze: list[pa.Table] = []
        self._validations: list[pa.Table] = []  # each validation attempt's rows, as log/validation-NNN.psylog holds them
        #: after finalise, with ``keep_gaze``: the attempts as validation.parquet would hold them (None: none ran)
        self.validations: pd.DataFrame | None = None
        #: after finalise: the trial table as arrow (None: it had repeated or unordered trials, converted at once)
        self.arrow_trials: pa.Table | None = None
        self._trials: pd.DataFrame | None = None
        self.gaze: pd.DataFrame | None = None

    def open(self, metadata: JsonMapping) -> set[int]:
        self.metadata = dict(metadata)
        return set()  # a fresh session: nothing to resume

    def append_trial(self, row: JsonMapping, frames: pa.Table | None, gaze: pa.Table | None = None) -> None:
        self._rows.append(tuple(map(row.get, self._names)))  # each schema column's value, None where absent
        if self.keeps_samples and gaze is not None and gaze.num_rows:  # frames: nothing a replication reads
            self._gaze.append(gaze)

    def append_gaze(self, gaze: pa.Table, key: int = -1) -> None:
        if self.keeps_samples and gaze.num_rows:  # samples after the last trial, as the durable log keeps them
            self._gaze.append(gaze)

    def validation_recorder(self) -> _MemoryValidations | None:
        """Where the session's gaze validations keep their attempts (psyop.session.validation.gaze_validator):
        in this log, not in a file under :attr:`paths` (no such folder); None when it keeps no samples."""
        return _MemoryValidations(self._validations) if self.keeps_samples else None

    def update_metadata(self, **fields: Any) -> None:  # Any: session.json values (JSON)
        self.metadata.update(fields)

    def update_run(self, **fields: Any) -> None:  # Any: a run's session.json values (JSON)
        return None  # one run, no session.json: nothing reads a replication's display record

    def close(self) -> None:
        return None

    def finalise(self, *, status: str, summary: JsonMapping | None = None) -> None:
        """The trial table as the durable log's salvage gives it (one row per trial, by trial): kept as arrow
        (:attr:`arrow_trials`) when the records came in ascending trial order, converted to pandas when
        :attr:`trials` is first read (:func:`analysis_trials` converts every session's at once)."""
        by_column = list(zip(*self._rows)) if self._rows else [() for _ in self._names]
        columns = {name: list(values) for name, values in zip(self._names, by_column)}
        table = pa.Table.from_pydict(columns, schema=self.trial_schema)
        if _ascending(columns["trial"]):  # dropping repeats and sorting would change nothing
            self.arrow_trials = table
        else:  # a re-run trial: its first record, by trial (converted first: its dtypes see every record)
            trials = table.to_pandas().drop_duplicates(subset="trial", keep="first").sort_values("trial", kind="stable")
            self._trials = trials.reset_index(drop=True)
        if self.keeps_samples:  # the stream in arrival order, as the durable log's salvage concatenates it
            self.gaze = (pa.concat_tables(self._gaze, promote_options="permissive").to_pandas() if self._gaze
                         else GAZE_SCHEMA.empty_table().to_pandas())
        if self.keeps_samples and self._validations:  # as recorded_validations reads the segments back
            self.validations = pa.concat_tables(self._validations, promote_options="permissive").to_pandas()
        self.metadata["status"] = status

    @property
    def finalised(self) -> bool:
        return self.arrow_trials is not None or self._trials is not None

    @property
    def trials(self) -> pd.DataFrame | None:
        """The trial table (None before finalise), as load_dataset reads one session's trials.parquet."""
        if self._trials is None and self.arrow_trials is not None:
            self._trials = self.arrow_trials.to_pandas()
        return self._trials


class _MemoryValidations:
    """A :class:`~psyop.session.validation.ValidationRecorder` into a list: each attempt's rows as arrow, converted
    as :class:`~psyop.session.log.validation_log.ValidationLog` converts them before writing."""

    def __init__(self, tables: list[pa.Table]) -> None:
        self._tables = tables

    def append(self, rows: pd.DataFrame, key: int) -> None:
        self._tables.append(pa.Table.from_pandas(rows[VALIDATION_SCHEMA.names], schema=VALIDATION_SCHEMA,
                                                 preserve_index=False))

    def close(self) -> None:
        return None


def _ascending(values: Sequence[object]) -> bool:
    """Whether ``values`` (trial numbers) strictly ascend: then dropping repeats and sorting changes nothing
    (the frame keeps to_pandas' RangeIndex, as reset_index would give it)."""
    return all(a < b for a, b in zip(values, values[1:]))  # type: ignore[operator]  # trial numbers: ints


def analysis_trials(logs: Sequence[MemoryLog], quality: QualitySection | None = None) -> pd.DataFrame:
    """The sessions' trials in one table, as ``load_dataset(data_root, study).trials`` returns them
    (sessions in the order of their trials.parquet paths; participant str, session int; practice
    and timed-out trials left out; with ``quality`` rules, the trials and participants they exclude
    left out, :func:`included`). The low-gaze count and warning of load_dataset and its attrs are
    not made: the power analysis reads none of them."""
    ordered = sorted(logs, key=lambda log: log.paths.trials_parquet)
    for log in ordered:
        if not log.finalised:
            raise RuntimeError(f"{log.paths.directory}: the session was not finalised")
    trials = concatenated_trials(ordered)
    if "participant" in trials:
        trials["participant"] = trials["participant"].astype(str)
    if "session" in trials:
        trials["session"] = trials["session"].astype(int)
    if "practice" in trials:
        trials = trials[~trials["practice"].fillna(False).astype(bool)].reset_index(drop=True)
    trials = dc.drop_timeouts(trials)
    return trials if quality is None else included(trials, ordered, quality)


def concatenated_trials(logs: Sequence[MemoryLog]) -> pd.DataFrame:
    """``pd.concat([log.trials for log in logs], ignore_index=True)``, converted from one arrow table when
    every log kept its arrow table and they share a schema: the same frame (a column's dtype is the one
    pandas' concat gives the sessions' dtypes: an integer column with a null anywhere is float64, a bool
    column with one is object, with the same values; tests/power/test_memory_log.py), for one to_pandas
    instead of one per session (a twentieth of a detection replication)."""
    tables = [log.arrow_trials for log in logs]
    arrow = [t for t in tables if t is not None]
    if logs and len(arrow) == len(tables) and all(t.schema.equals(arrow[0].schema) for t in arrow):
        return pa.concat_tables(arrow).to_pandas()
    return pd.concat([log.trials for log in logs], ignore_index=True)


def included(trials: pd.DataFrame, logs: Sequence[MemoryLog], quality: QualitySection) -> pd.DataFrame:
    """``trials`` less what ``quality`` excludes, as psyop.quality.included.include leaves them in
    load_dataset: every session measured (:func:`session_measures`), the rules applied, the
    excluded (participant, session, trial) rows and participants dropped."""
    from psyop.quality.rules import apply_rules, included_mask

    plans: dict[tuple[object, object], SessionPlan] = {}
    measures = pd.concat([session_measures(log, plans) for log in logs], ignore_index=True)
    keep = included_mask(trials, apply_rules(measures, quality))
    return trials[keep].reset_index(drop=True)


def session_measures(log: MemoryLog, plans: dict[tuple[object, object], SessionPlan]) -> pd.DataFrame:
    """The per-trial quality measures of one in-memory session, computed as
    psyop.quality.session.measure_session computes them from the finalised files (the plan of the
    recorded protocol text, the simulated tracker's nominal rate and stream, the same measure calls,
    the gaze validations the session kept in memory for the ``validation_*`` measures);
    ``plans`` caches the compiled plan per protocol text."""
    from psyop.protocol.validation import VALIDATION_MEASURES
    from psyop.quality.session import cached_plan, stream_measures, stream_of
    from psyop.quality.validation import trial_validation_measures
    from psyop.session.log.record import record_of

    if log.trials is None or log.gaze is None:
        raise RuntimeError(f"{log.paths.directory}: the session was not finalised with its raw gaze kept")
    meta = log.metadata
    meta_path = Path(log.paths.directory) / dc.SESSION_METADATA_FILE
    record = record_of(meta, meta_path)
    s = stream_of(cached_plan(record, meta_path, plans), record, log.trials, log.gaze)
    measures, _ = stream_measures(s)
    validation = trial_validation_measures(s.trials, log.validations)  # NaN: no gaze_validation
    for name in VALIDATION_MEASURES:
        measures[name] = validation[name].to_numpy()
    measures.insert(0, "session", s.session)
    measures.insert(0, "participant", s.participant)
    return measures
