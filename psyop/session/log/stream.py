"""One append-only log segment of checksummed records, made durable record by record.

Format (``*.psylog``, little-endian): a sequence of records, each a 32-byte header

    magic b"PSYR" | version u8 | kind u8 | reserved u16 | key i64 | length u32 |
    payload_crc32 u32 | schema_crc32 u32 | header_crc32 u32 (of the 28 bytes before it)

followed by ``length`` payload bytes. Kinds: SCHEMA (the Arrow schema, written twice so
that one damaged copy is survivable), BATCH (one Arrow IPC record-batch message; ``key``
is its trial number) and END (written by a clean close; ``key`` is the number of batch
records). Every byte is covered by a CRC32, so a flipped byte anywhere is detected, and
the reader validates the framing and checksums *before* any byte reaches pyarrow (pyarrow
may abort the process on a corrupt IPC message). A damaged record is skipped and reported;
the reader resynchronises on the next valid header and keeps every intact record after it.

Why not a plain Arrow IPC stream (the format before, still read from ``*.arrows``): its
messages carry no checksum, a flip inside a value went undetected, and a flip in the
framing made the reader stop (dropping every later trial) or abort the process.
"""

from __future__ import annotations

import os
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import pyarrow as pa

from psyop.atomic import fsync_dir

MAGIC = b"PSYR"
VERSION = 1
KIND_SCHEMA, KIND_BATCH, KIND_END = 1, 2, 3
_HEAD = struct.Struct("<4sBBHqIII")
_CRC = struct.Struct("<I")
HEADER_BYTES = _HEAD.size + _CRC.size  # 32
#: A header announcing more than this is treated as damaged (no valid record is this large).
MAX_RECORD_BYTES = 1 << 30
NO_KEY = -1


def _header(kind: int, key: int, payload: bytes | memoryview, schema_crc: int) -> bytes:
    head = _HEAD.pack(MAGIC, VERSION, kind, 0, key, len(payload), zlib.crc32(payload), schema_crc)
    return head + _CRC.pack(zlib.crc32(head))


class DurableStreamWriter:
    """Append record batches to ``path``; each ``append`` is one checksummed record, fsynced.

    The file is created exclusively and never follows a symlink: a segment is never
    reopened for appending, because its tail may be torn after a crash.
    """

    def __init__(self, path: Path, schema: pa.Schema, *, fsync: bool = True) -> None:
        self.path = Path(path)
        self.schema = schema
        self._fsync = fsync
        fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0), 0o644)
        self._file = os.fdopen(fd, "wb", buffering=0)  # lifetime managed by close()
        schema_bytes = schema.serialize().to_pybytes()
        self._schema_crc = zlib.crc32(schema_bytes)
        self._n_batches = 0
        record = _header(KIND_SCHEMA, 0, schema_bytes, self._schema_crc) + schema_bytes
        try:
            self._write_all(record + record)  # two copies: one damaged copy loses nothing
            self._sync()
            fsync_dir(self.path.parent)  # the new segment's name is durable (an error is an error)
        except OSError as exc:
            self._file.close()
            raise OSError(exc.errno, exc.strerror, exc.filename or str(self.path)) from exc

    def append(self, table: pa.Table | pa.RecordBatch, key: int = NO_KEY) -> None:
        """Write ``table`` (cast to the segment schema) as one record; durable on return.

        ``key`` names what the record holds (the trial number) so that a damaged record
        can still be reported by trial.
        """
        if isinstance(table, pa.RecordBatch):
            table = pa.Table.from_batches([table])
        if table.schema != self.schema:
            table = table.select(self.schema.names).cast(self.schema)
        batches = table.combine_chunks().to_batches()  # one batch: every column is one chunk now
        batch = batches[0] if batches else pa.RecordBatch.from_pylist([], schema=self.schema)
        payload = batch.serialize().to_pybytes()
        self._write_all(_header(KIND_BATCH, int(key), payload, self._schema_crc) + payload)
        self._n_batches += 1
        self._sync()

    def _write_all(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            written = os.write(self._file.fileno(), view)
            view = view[written:]

    def _sync(self) -> None:
        if self._fsync:
            # fdatasync: the appended bytes and the new file size, without atime/mtime
            getattr(os, "fdatasync", os.fsync)(self._file.fileno())

    @property
    def closed(self) -> bool:
        return self._file.closed

    def close(self) -> None:
        """Write the end record and close. Safe to call twice."""
        if self._file.closed:
            return
        try:
            self._write_all(_header(KIND_END, self._n_batches, b"", self._schema_crc))
            self._sync()
        finally:
            self._file.close()

    def __enter__(self) -> DurableStreamWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass(frozen=True)
class Damage:
    """A damaged stretch of a segment: where, how long, which trial if known, and why."""

    offset: int
    length: int
    key: int | None  # trial number from an intact header; None when the header itself is damaged
    reason: str  # 'checksum', 'truncated', 'unreadable', 'undecodable'
    kind: str  # 'schema', 'batch', 'end' or 'unknown'

    def as_dict(self) -> dict[str, object]:
        return {"offset": self.offset, "length": self.length, "trial": self.key, "reason": self.reason, "record": self.kind}


@dataclass
class SegmentRead:
    """What a segment yielded: the intact batches (with their keys) and every damage found."""

    schema: pa.Schema | None
    table: pa.Table | None
    keys: list[int] = field(default_factory=list)
    damage: list[Damage] = field(default_factory=list)
    clean_end: bool = False
    schema_crc: int | None = None

    @property
    def torn(self) -> bool:
        return not self.clean_end


_KIND_NAMES = {KIND_SCHEMA: "schema", KIND_BATCH: "batch", KIND_END: "end"}


def _segment_schema(schema_bytes: bytes | None, schema_crc: int | None, schema_hint: pa.Schema | None,
                    raw: list[tuple[int, int, int, bytes]]) -> tuple[pa.Schema | None, int | None]:
    """The segment's schema and its checksum: its own copy, else ``schema_hint`` if every batch names its checksum."""
    schema: pa.Schema | None = None
    if schema_bytes is not None:
        try:
            schema = pa.ipc.read_schema(pa.py_buffer(schema_bytes))
        except (pa.ArrowException, ValueError):  # pragma: no cover - checksummed bytes we wrote
            schema = None
    if schema is None and schema_hint is not None:
        hint_crc = zlib.crc32(schema_hint.serialize().to_pybytes())
        if raw and all(crc == hint_crc for _, _, crc, _ in raw):
            schema, schema_crc = schema_hint, hint_crc
    return schema, schema_crc


def read_segment(path: Path, schema_hint: pa.Schema | None = None) -> SegmentRead:
    """Salvage every intact record of a ``*.psylog`` segment; never raises on its content.

    ``schema_hint`` (another segment's schema) is used only if both schema copies here are
    damaged and its checksum equals the one the batch records name.
    """
    data = Path(path).read_bytes()
    n = len(data)
    pos = 0
    schema_bytes: bytes | None = None
    schema_crc_seen: int | None = None
    raw: list[tuple[int, int, int, bytes]] = []  # (offset, key, schema_crc, payload)
    damage: list[Damage] = []
    clean_end = False
    while pos < n:
        parsed = _parse_header(data, pos)
        if parsed is None:
            nxt = data.find(MAGIC, pos + 1)
            while nxt != -1 and _parse_header(data, nxt) is None:
                nxt = data.find(MAGIC, nxt + 1)
            end = n if nxt == -1 else nxt
            reason = "truncated" if nxt == -1 and n - pos < HEADER_BYTES else "unreadable"
            damage.append(Damage(pos, end - pos, None, reason, "unknown"))
            pos = end
            continue
        kind, key, length, payload_crc, schema_crc = parsed
        start = pos + HEADER_BYTES
        end = start + length
        kind_name = _KIND_NAMES[kind]
        if end > n:
            damage.append(Damage(pos, n - pos, key if kind == KIND_BATCH else None, "truncated", kind_name))
            break
        payload = data[start:end]
        if zlib.crc32(payload) != payload_crc:
            damage.append(Damage(pos, end - pos, key if kind == KIND_BATCH else None, "checksum", kind_name))
        elif kind == KIND_SCHEMA:
            if schema_bytes is None:
                schema_bytes, schema_crc_seen = payload, schema_crc
        elif kind == KIND_BATCH:
            raw.append((pos, key, schema_crc, payload))
        else:
            clean_end = True
        pos = end
    schema, schema_crc_seen = _segment_schema(schema_bytes, schema_crc_seen, schema_hint, raw)
    batches: list[pa.RecordBatch] = []
    keys: list[int] = []
    for offset, key, crc, payload in raw:
        if schema is None or crc != schema_crc_seen:
            damage.append(Damage(offset, HEADER_BYTES + len(payload), key, "undecodable", "batch"))
            continue
        try:
            batches.append(pa.ipc.read_record_batch(pa.py_buffer(payload), schema))
            keys.append(key)
        except (pa.ArrowException, ValueError, OSError):  # pragma: no cover - checksummed bytes we wrote
            damage.append(Damage(offset, HEADER_BYTES + len(payload), key, "undecodable", "batch"))
    table = pa.Table.from_batches(batches, schema=schema) if schema is not None else None
    damage.sort(key=lambda d: d.offset)
    return SegmentRead(schema, table, keys, damage, clean_end, schema_crc_seen)


def _parse_header(data: bytes, pos: int) -> tuple[int, int, int, int, int] | None:
    if len(data) - pos < HEADER_BYTES or data[pos:pos + 4] != MAGIC:
        return None
    head = data[pos:pos + _HEAD.size]
    (crc,) = _CRC.unpack_from(data, pos + _HEAD.size)
    if zlib.crc32(head) != crc:
        return None
    _, version, kind, _, key, length, payload_crc, schema_crc = _HEAD.unpack(head)
    if version != VERSION or kind not in _KIND_NAMES or length > MAX_RECORD_BYTES:
        return None
    return kind, key, length, payload_crc, schema_crc


def read_stream_tolerant(path: Path) -> tuple[pa.Table | None, bool]:
    """Read every intact batch of a segment; return (table or None, torn).

    ``torn`` is True when the segment did not end cleanly or holds damage. Segments in
    the checksummed format are salvaged record by record (:func:`read_segment`); legacy
    Arrow IPC streams (``*.arrows``, written before checksums) are read up to the first
    incomplete message.
    """
    path = Path(path)
    if is_legacy_ipc(path):
        return _read_legacy_ipc(path)
    read = read_segment(path)
    return read.table, read.torn or bool(read.damage)


def is_legacy_ipc(path: Path) -> bool:
    """True for a segment written before checksums (a plain Arrow IPC stream)."""
    try:
        with open(path, "rb") as handle:
            head = handle.read(4)
    except OSError:
        return False
    return head == b"\xff\xff\xff\xff" and Path(path).suffix == ".arrows"


#: Reads a legacy Arrow IPC stream in a child process: pyarrow may abort (``Check failed``,
#: exit 134) or exhaust memory on a corrupt IPC message, which must not take the session or
#: ``psyop recover`` with it. The child re-serialises each batch it could read, framed as
#: kind byte + u64 length + bytes; whatever arrived before it failed is kept.
_LEGACY_CHILD = r"""
import resource, sys
import pyarrow as pa
limit = 4 << 30
resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
out = sys.stdout.buffer
def put(kind, data=b""):
    out.write(kind + len(data).to_bytes(8, "little") + data)
    out.flush()
with open(sys.argv[1], "rb") as handle:
    try:
        reader = pa.ipc.open_stream(handle)
    except Exception:
        sys.exit(3)
    put(b"S", reader.schema.serialize().to_pybytes())
    while True:
        try:
            batch = reader.read_next_batch()
        except StopIteration:
            put(b"E")
            break
        except BaseException:
            put(b"T")
            break
        put(b"B", batch.serialize().to_pybytes())
"""


def _read_legacy_ipc(path: Path, timeout_s: float = 120.0) -> tuple[pa.Table | None, bool]:
    import subprocess
    import sys

    try:
        done = subprocess.run([sys.executable, "-c", _LEGACY_CHILD, str(path)], capture_output=True,
                              timeout=timeout_s, check=False)
        data = done.stdout
    except subprocess.TimeoutExpired as exc:
        data = exc.stdout or b""
    schema: pa.Schema | None = None
    batches: list[pa.RecordBatch] = []
    clean = False
    pos = 0
    while pos + 9 <= len(data):
        kind, length = data[pos:pos + 1], int.from_bytes(data[pos + 1:pos + 9], "little")
        payload = data[pos + 9:pos + 9 + length]
        if len(payload) < length:
            break
        pos += 9 + length
        if kind == b"S":
            schema = pa.ipc.read_schema(pa.py_buffer(payload))
        elif kind == b"B" and schema is not None:
            batches.append(pa.ipc.read_record_batch(pa.py_buffer(payload), schema))
        elif kind == b"E":
            clean = True
    if schema is None:
        return None, True
    return pa.Table.from_batches(batches, schema=schema), not clean
