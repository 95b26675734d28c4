"""One append-only Arrow IPC stream file, made durable batch by batch.

Why IPC streams: a parquet file killed before its footer is written is unreadable
(measured, DESIGN.md), while an IPC stream is a sequence of self-delimited messages;
a reader that stops at the first incomplete message recovers everything before it.
"""

from __future__ import annotations

import os
from pathlib import Path

import pyarrow as pa


class DurableStreamWriter:
    """Append record batches to ``path``; each ``append`` is flushed and fsynced.

    The file is created exclusively: a segment is never reopened for appending,
    because its tail may be torn after a crash.
    """

    def __init__(self, path: Path, schema: pa.Schema, *, fsync: bool = True) -> None:
        self.path = Path(path)
        self.schema = schema
        self._fsync = fsync
        self._file = open(self.path, "xb")  # noqa: SIM115 - lifetime managed by close()
        self._writer = pa.ipc.new_stream(self._file, schema)
        self._sync()
        _fsync_dir(self.path.parent)

    def append(self, table: pa.Table | pa.RecordBatch) -> None:
        """Write ``table`` (cast to the stream schema) and make it durable before returning."""
        if isinstance(table, pa.RecordBatch):
            table = pa.Table.from_batches([table])
        if table.schema != self.schema:
            table = table.select(self.schema.names).cast(self.schema)
        for batch in table.to_batches():
            self._writer.write_batch(batch)
        self._sync()

    def _sync(self) -> None:
        self._file.flush()
        if self._fsync:
            # fdatasync: the appended bytes and the new file size, without atime/mtime
            getattr(os, "fdatasync", os.fsync)(self._file.fileno())

    def close(self) -> None:
        """Write the end-of-stream marker and close. Safe to call twice."""
        if self._file.closed:
            return
        self._writer.close()
        self._sync()
        self._file.close()

    def __enter__(self) -> DurableStreamWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_stream_tolerant(path: Path) -> tuple[pa.Table | None, bool]:
    """Read every complete batch of an IPC stream; return (table or None, torn).

    ``torn`` is True when the stream ended without its end-of-stream marker or with an
    incomplete batch (the writer was killed). A file too short to hold a schema gives
    (None, True).
    """
    batches: list[pa.RecordBatch] = []
    with open(path, "rb") as handle:
        try:
            reader = pa.ipc.open_stream(handle)
        except (pa.ArrowInvalid, OSError, EOFError):
            return None, True
        torn = False
        while True:
            try:
                batch = reader.read_next_batch()
            except StopIteration:
                break
            except (pa.ArrowInvalid, OSError, EOFError):
                torn = True
                break
            batches.append(batch)
        return pa.Table.from_batches(batches, schema=reader.schema), torn


def _fsync_dir(directory: Path) -> None:
    """Make a newly created directory entry durable (POSIX); ignore where unsupported."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
