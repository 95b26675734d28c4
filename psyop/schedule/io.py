"""Write and read schedules as parquet, byte-identical for the same protocol and seed."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from psyop.protocol.model import Protocol


def schedule_table(schedule: pd.DataFrame, protocol: Protocol, seed: int) -> pa.Table:
    """Arrow table with the protocol hash, name and seed in the schema metadata."""
    table = pa.Table.from_pandas(schedule, preserve_index=False)
    metadata = dict(table.schema.metadata or {})
    metadata.update({
        b"psyop.study": protocol.study.name.encode(),
        b"psyop.protocol_sha256": protocol.source_sha256.encode(),
        b"psyop.seed": str(seed).encode(),
    })
    return table.replace_schema_metadata(metadata)


def write_schedule(schedule: pd.DataFrame, protocol: Protocol, seed: int, path: str | Path) -> Path:
    """Write ``schedule`` to ``path`` (parquet, zstd, no timestamps, so bytes are reproducible)."""
    path = Path(path)
    pq.write_table(schedule_table(schedule, protocol, seed), path, compression="zstd", write_statistics=True)
    return path


def read_schedule(path: str | Path) -> pd.DataFrame:
    """Read a schedule written by :func:`write_schedule`."""
    return pd.read_parquet(path)
