"""The gaze validations of a session, logged durably: one checksummed record per validation attempt.

Segments ``log/validation-NNN.psylog`` (one per run, made on the run's first validation) hold the rows
of :data:`VALIDATION_SCHEMA`; finalisation writes them, in order, to ``validation.parquet`` (checksummed
in session.json like the other session files). A session whose protocol has no ``gaze_validation:``
writes neither. docs/data.md "validation.parquet".
"""

from __future__ import annotations

from typing import Protocol

import pandas as pd
import pyarrow as pa

from psyop.session.log.layout import SEGMENT_SUFFIX, SessionPaths
from psyop.session.log.stream import DurableStreamWriter, read_segment

#: one row per point of each attempt, then the attempt's overall row (point -1)
VALIDATION_SCHEMA = pa.schema([
    ("run", pa.int32()), ("validation", pa.int32()), ("when", pa.string()), ("before_trial", pa.int64()),
    ("attempt", pa.int32()), ("point", pa.int32()), ("target_az_deg", pa.float64()), ("target_el_deg", pa.float64()),
    ("distance_m", pa.float64()), ("start_s", pa.float64()), ("end_s", pa.float64()),
    ("n_samples", pa.int64()), ("n_valid", pa.int64()),
    ("mean_error_deg", pa.float64()), ("max_error_deg", pa.float64()),
    ("precision_rms_s2s_deg", pa.float64()), ("precision_sd_deg", pa.float64()),
    ("left_mean_error_deg", pa.float64()), ("right_mean_error_deg", pa.float64()),
    ("passed", pa.bool_()),
])


class ValidationRecorder(Protocol):
    """What keeps a run's validation attempts: :class:`ValidationLog` (durable, validation.parquet at finalisation),
    or a log's own in-memory record (psyop power's MemoryLog)."""

    def append(self, rows: pd.DataFrame, key: int) -> None: ...
    def close(self) -> None: ...


class ValidationLog:
    """Appends validation attempts to this run's segment (created on the first), each durable on return."""

    def __init__(self, paths: SessionPaths, run: int, *, fsync: bool = True) -> None:
        self.paths, self.run, self._fsync = paths, int(run), fsync
        self._writer: DurableStreamWriter | None = None

    def append(self, rows: pd.DataFrame, key: int) -> None:
        """Make one attempt's rows (:data:`VALIDATION_SCHEMA` columns) durable; ``key``: its validation number."""
        if self._writer is None:
            self._writer = DurableStreamWriter(self.paths.log_dir / f"validation-{self.run:03d}{SEGMENT_SUFFIX}",
                                               VALIDATION_SCHEMA, fsync=self._fsync)
        self._writer.append(pa.Table.from_pandas(rows[VALIDATION_SCHEMA.names], schema=VALIDATION_SCHEMA,
                                                 preserve_index=False), key=key)

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()


def recorded_validations(paths: SessionPaths) -> pd.DataFrame | None:
    """Every intact validation record of the session's segments, in run order (None: no segment, i.e.
    the protocol has no validation or none has run)."""
    segments = paths.segments("validation")
    if not segments:
        return None
    tables = [t for t in (read_segment(s).table for s in segments) if t is not None]
    if not tables:
        return VALIDATION_SCHEMA.empty_table().to_pandas()
    return pa.concat_tables(tables, promote_options="permissive").to_pandas().reset_index(drop=True)
