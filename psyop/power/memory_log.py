"""The in-memory session log of a power replication, and the analysis table built from it.

A replication's sessions are throwaway: nobody resumes, recovers or reads them after the
analysis. :class:`MemoryLog` is what ``run_session`` records into for them (its
``store_factory``): each trial row, converted with the session's own trial schema exactly as the
durable :class:`~psyop.session.log.store.SessionStore` converts it, is kept in memory; frames and
raw gaze samples are not built (``keeps_samples`` false) and nothing is written, fsynced or
locked. :func:`analysis_trials` then hands the sessions' tables to the analysis as
:func:`psyop.statistics.dataset.load_dataset` would have read them back from their
trials.parquet files (same order, same types, practice and timed-out trials left out).
``tests/power/test_memory_log.py`` holds the two to the same frame, column by column, and the
whole power table byte for byte, for every shipped study.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import pandas as pd
import pyarrow as pa

from psyop import datacontract as dc
from psyop.session.log.layout import SessionPaths
from psyop.records import JsonMapping, JsonObject


class MemoryLog:
    """A session log held in memory (see the module docstring); :attr:`trials` after finalise."""

    keeps_samples = False

    def __init__(self, paths: SessionPaths, trial_schema: pa.Schema) -> None:
        self.paths = paths
        self.trial_schema = trial_schema
        self.run_index = 0
        self.metadata: JsonObject = {}
        self._rows: list[JsonObject] = []
        self.trials: pd.DataFrame | None = None

    def open(self, metadata: JsonMapping) -> set[int]:
        self.metadata = dict(metadata)
        return set()  # a fresh session: nothing to resume

    def append_trial(self, row: JsonMapping, frames: pa.Table | None, gaze: pa.Table | None = None) -> None:
        self._rows.append({name: row.get(name) for name in self.trial_schema.names})

    def append_gaze(self, gaze: pa.Table, key: int = -1) -> None:
        return None  # raw gaze samples: no analysis of a replication reads them

    def update_metadata(self, **fields: Any) -> None:  # Any: session.json values (JSON)
        self.metadata.update(fields)

    def update_run(self, **fields: Any) -> None:  # Any: a run's session.json values (JSON)
        return None  # one run, no session.json: nothing reads a replication's display record

    def close(self) -> None:
        return None

    def finalise(self, *, status: str, summary: JsonMapping | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
        """The trial table as the durable log's salvage gives it (one row per trial, by trial)."""
        columns = {name: [r[name] for r in self._rows] for name in self.trial_schema.names}
        trials = pa.Table.from_pydict(columns, schema=self.trial_schema).to_pandas()
        trials = trials.drop_duplicates(subset="trial", keep="first").sort_values("trial", kind="stable")
        self.trials = trials.reset_index(drop=True)
        self.metadata["status"] = status
        return self.trials, pd.DataFrame()


def analysis_trials(logs: Sequence[MemoryLog]) -> pd.DataFrame:
    """The sessions' trials in one table, as ``load_dataset(data_root, study).trials`` returns them
    (sessions in the order of their trials.parquet paths; participant str, session int; practice
    and timed-out trials left out). The low-gaze count and warning of load_dataset are not made:
    the power analysis reads neither."""
    ordered = sorted(logs, key=lambda log: log.paths.trials_parquet)
    frames = []
    for log in ordered:
        if log.trials is None:
            raise RuntimeError(f"{log.paths.directory}: the session was not finalised")
        frames.append(log.trials)
    trials = pd.concat(frames, ignore_index=True)
    if "participant" in trials:
        trials["participant"] = trials["participant"].astype(str)
    if "session" in trials:
        trials["session"] = trials["session"].astype(int)
    if "practice" in trials:
        trials = trials[~trials["practice"].fillna(False).astype(bool)].reset_index(drop=True)
    return dc.drop_timeouts(trials)
