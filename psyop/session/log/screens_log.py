"""The screens around a session's trials and the questionnaire answers, logged durably (psyop.session.screens).

Per run, segments ``log/events-NNN.psylog`` (one record per screen shown: :data:`EVENTS_SCHEMA`) and
``log/questionnaires-NNN.psylog`` (one record per questionnaire item answered: :data:`QUESTIONNAIRE_SCHEMA`),
each created on its first record, checksummed and fsynced record by record like the trial log. Finalisation
writes them, in run order, to ``events.parquet`` and ``questionnaires.parquet`` in the session folder,
recorded in session.json's ``finalised_files`` (psyop.finalised) so that every reader verifies them. A
session whose protocol has no ``session:`` section writes neither.
"""

from __future__ import annotations

from typing import Protocol

import pyarrow as pa

from psyop.session.log.layout import SEGMENT_SUFFIX, SessionPaths
from psyop.session.log.stream import DurableStreamWriter, read_segment
from psyop.session.rows import JsonMapping

#: one row per screen shown: what it was, when, how long the participant took, what ended it
EVENTS_SCHEMA = pa.schema([
    ("run", pa.int32()), ("seq", pa.int32()), ("screen", pa.string()), ("name", pa.string()),
    ("page", pa.int32()), ("n_pages", pa.int32()), ("when", pa.string()), ("before_trial", pa.int64()),
    ("block", pa.int64()), ("after_trial", pa.int64()), ("trials_done", pa.int64()), ("trials_left", pa.int64()),
    ("start_s", pa.float64()), ("end_s", pa.float64()), ("duration_s", pa.float64()),
    ("ended_by", pa.string()), ("text", pa.string()),
])

#: one row per questionnaire item: who, which questionnaire and administration, the item and its answer
QUESTIONNAIRE_SCHEMA = pa.schema([
    ("run", pa.int32()), ("study", pa.string()), ("participant", pa.string()), ("session", pa.int32()),
    ("questionnaire", pa.string()), ("administration", pa.int32()), ("when", pa.string()),
    ("before_trial", pa.int64()), ("item", pa.int32()), ("item_text", pa.string()),
    ("answer", pa.int32()), ("answer_label", pa.string()), ("scale_points", pa.int32()),
    ("answered_by", pa.string()), ("start_s", pa.float64()), ("end_s", pa.float64()),
])


class ScreenRecorder(Protocol):
    """What keeps a run's screens and answers: :class:`ScreenLog` (durable), or nothing (None) for a log that
    keeps only what its caller reads (psyop power's in-memory log)."""

    def append_event(self, row: JsonMapping) -> None: ...
    def append_answers(self, rows: list[JsonMapping]) -> None: ...
    def close(self) -> None: ...


def _table(rows: list[JsonMapping], schema: pa.Schema) -> pa.Table:
    return pa.Table.from_pydict({name: [row.get(name) for row in rows] for name in schema.names}, schema=schema)


class ScreenLog:
    """Appends this run's screens and answers to its segments (each created on its first record), each record
    durable on return."""

    def __init__(self, paths: SessionPaths, run: int, *, fsync: bool = True) -> None:
        self.paths, self.run, self._fsync = paths, int(run), fsync
        self._events: DurableStreamWriter | None = None
        self._answers: DurableStreamWriter | None = None
        self._n = 0

    def append_event(self, row: JsonMapping) -> None:
        if self._events is None:
            self._events = DurableStreamWriter(self.paths.log_dir / f"events-{self.run:03d}{SEGMENT_SUFFIX}",
                                               EVENTS_SCHEMA, fsync=self._fsync)
        self._n += 1
        self._events.append(_table([{**row, "seq": self._n}], EVENTS_SCHEMA), key=self._n)

    def append_answers(self, rows: list[JsonMapping]) -> None:
        if not rows:
            return
        if self._answers is None:
            self._answers = DurableStreamWriter(
                self.paths.log_dir / f"questionnaires-{self.run:03d}{SEGMENT_SUFFIX}", QUESTIONNAIRE_SCHEMA,
                fsync=self._fsync)
        self._answers.append(_table(rows, QUESTIONNAIRE_SCHEMA), key=int(rows[0]["administration"]))

    def close(self) -> None:
        for writer in (self._events, self._answers):
            if writer is not None:
                writer.close()


def recorded_screen_table(paths: SessionPaths, kind: str) -> pa.Table | None:
    """Every intact record of the session's ``kind`` segments ('events' or 'questionnaires'), in run order
    (None: no segment: the protocol has no such screens, or none was shown)."""
    schema = EVENTS_SCHEMA if kind == "events" else QUESTIONNAIRE_SCHEMA
    segments = paths.segments(kind)
    if not segments:
        return None
    tables = [t for t in (read_segment(s).table for s in segments) if t is not None]
    if not tables:
        return schema.empty_table()
    return pa.concat_tables(tables, promote_options="permissive")
