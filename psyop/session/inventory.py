"""Which sessions a data root holds, per study: how many, simulated or real, complete or not.

``make figures`` prints this before it draws anything, and refuses a study whose sessions
mix simulated and real participants (the figures would pool them) unless asked to (MIX=1).

A session is a ``<study>/sub-<ID>/ses-<N>/`` folder holding a session.json, a trials.parquet
or a log. Everything in data/ is read defensively: only regular files within size limits
(a FIFO would block, a link to /dev/zero never ends: both are a UserError naming the path),
and a session reached twice (a linked folder, a trials.parquet linked into another session)
is refused, naming both paths. Whether a session is simulated is decided from every record
that says so, and the durable ones cannot be deleted by accident: session.json, the
finalised trials.parquet (its ``psyop.simulated`` schema metadata) and the log's own header
(the first schema record of each trial segment). A session is simulated only when every one
of them that exists says so; a session none of them describes counts as real. Each session's
finalised files are checked against the SHA-256 recorded in its session.json (psyop.finalised). session.json
is read as its typed record (psyop.session.log.record.read_record_file).
"""

from __future__ import annotations

import json
import os
import shlex
import stat
import zlib
from dataclasses import dataclass
from pathlib import Path

from psyop import datacontract as dc
from psyop.errors import UserError
from psyop.finalised import finalisation_interrupted, verify_session
from psyop.input_files import MAX_LOG_TABLE_BYTES, InputFile
from psyop.session.log.record import SessionRecord as RecordedSession, read_record_file

#: the largest log segment header read to learn a session's identity (a schema record is a few kB)
MAX_SCHEMA_RECORD_BYTES = 1 << 20

_TRIALS_FILE = InputFile(what="trials.parquet", give="a session's trials.parquet must be a regular file",
                         max_bytes=MAX_LOG_TABLE_BYTES, typical="a session's trials.parquet is a few MB",
                         not_found="no file {path}")


@dataclass(frozen=True)
class StudySessions:
    study: str
    n_simulated: int
    n_real: int
    n_incomplete: int
    participants: tuple[str, ...]
    #: sessions with no record saying simulated or not (counted as real), as ``sub-X/ses-N``
    undescribed: tuple[str, ...] = ()
    #: sessions whose finalisation was interrupted (counted as incomplete), as their directories
    unfinished: tuple[Path, ...] = ()

    @property
    def mixed(self) -> bool:
        return self.n_simulated > 0 and self.n_real > 0

    def describe(self) -> str:
        kinds = [f"{n} {label}" for n, label in ((self.n_simulated, "simulated"), (self.n_real, "real")) if n]
        extra = f", {self.n_incomplete} incomplete" if self.n_incomplete else ""
        if self.undescribed:
            extra += f"; no record says simulated, counted as real: {', '.join(self.undescribed[:5])}"
        if self.unfinished:
            extra += ("; finalisation interrupted, nothing lost (finish it: "
                      + "; ".join(f"`psyop recover {shlex.quote(str(d))}`" for d in self.unfinished[:5])
                      + (f"; and {len(self.unfinished) - 5} more" if len(self.unfinished) > 5 else "") + ")")
        return f"{self.study}: {self.n_simulated + self.n_real} sessions ({', '.join(kinds)}{extra})"


@dataclass(frozen=True)
class SessionRecord:
    """One session folder as the inventory found it."""

    directory: Path
    participant: str
    simulated: bool | None  # None: no record says
    complete: bool
    sources: tuple[str, ...]  # which records decided ``simulated``
    #: a finalisation (of a run or a recover) did not finish (psyop.finalised.finalisation_interrupted)
    unfinished: bool = False


def _regular(path: Path) -> os.stat_result | None:
    """``os.stat`` of ``path`` when it exists (None if not); a UserError unless a regular file."""
    try:
        info = os.stat(path)
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise UserError(f"cannot read: {exc.strerror}", str(path)) from None
    if not stat.S_ISREG(info.st_mode):
        kind = "a FIFO" if stat.S_ISFIFO(info.st_mode) else "a device" if stat.S_ISCHR(info.st_mode) or \
            stat.S_ISBLK(info.st_mode) else "a folder" if stat.S_ISDIR(info.st_mode) else "not a regular file"
        raise UserError(f"{path.name} is {kind}, not a session file; remove it (or restore the file)", str(path))
    return info


def _read_record(path: Path) -> RecordedSession | None:
    """The session.json at ``path`` as its typed record (None if absent); a FIFO, device or folder, or a
    damaged file, is a UserError naming it."""
    return None if _regular(path) is None else read_record_file(path)


def _parquet_simulated(path: Path) -> bool | None:
    """``psyop.simulated`` from a finalised trials.parquet's schema metadata (None if absent or
    unreadable: the loader names a damaged table)."""
    import pyarrow.parquet as pq

    try:
        metadata = pq.read_schema(path).metadata or {}
    except Exception:  # noqa: BLE001 - a damaged table says nothing here
        return None
    value = metadata.get(dc.SIMULATED_METADATA_KEY.encode())
    return None if value is None else json.loads(value) is True


def _segment_simulated(log_dir: Path) -> bool | None:
    """``psyop.simulated`` from the log's own header: the first schema record of a trial segment."""
    from psyop.session.log.stream import HEADER_BYTES, KIND_SCHEMA, _parse_header

    values = []
    for segment in sorted(log_dir.glob("trials-*.psylog")) if log_dir.is_dir() else []:
        if _regular(segment) is None:
            continue
        with open(segment, "rb") as handle:
            parsed = _parse_header(handle.read(HEADER_BYTES), 0)
            if parsed is None or parsed[0] != KIND_SCHEMA or parsed[2] > MAX_SCHEMA_RECORD_BYTES:
                continue  # a damaged first copy: the segment says nothing here
            payload = handle.read(parsed[2])
        if zlib.crc32(payload) != parsed[3]:
            continue
        try:
            import pyarrow as pa

            schema = pa.ipc.read_schema(pa.py_buffer(payload))
        except Exception:  # noqa: BLE001 - a damaged copy: the segment says nothing
            continue
        value = (schema.metadata or {}).get(dc.SIMULATED_METADATA_KEY.encode())
        if value is not None:
            values.append(json.loads(value) is True)
    return None if not values else all(values)


def session_record(directory: Path, data_root: Path) -> SessionRecord | None:
    """What ``directory`` (``<study>/sub-X/ses-N``) holds; None when it holds no session."""
    meta = _read_record(directory / dc.SESSION_METADATA_FILE)
    trials = directory / dc.TRIALS_FILE
    trials_info = _regular(trials)
    if trials_info is not None:
        _TRIALS_FILE.check(trials)
    log_dir = directory / dc.LOG_DIR
    if meta is None and trials_info is None and not log_dir.is_dir():
        return None
    said: dict[str, bool] = {}
    if meta is not None and meta.simulated is not None:
        said["session.json"] = meta.simulated
    if trials_info is not None and (value := _parquet_simulated(trials)) is not None:
        said["trials.parquet"] = value
    if (value := _segment_simulated(log_dir)) is not None:
        said["log header"] = value
    simulated = None if not said else all(said.values())
    unfinished = meta is not None and finalisation_interrupted(meta.raw, directory)
    complete = meta is not None and meta.status == "complete" and not unfinished
    return SessionRecord(directory, directory.parent.name.removeprefix("sub-"), simulated, complete, tuple(said),
                         unfinished)


def session_records(data_root: Path, *, verify: bool = True) -> dict[str, list[SessionRecord]]:
    """Every session folder under ``data_root``, per study; a folder or file reached twice
    (through a link) is a UserError naming both paths. With ``verify``, each session's finalised
    files must match the SHA-256 its session.json recorded (:func:`psyop.finalised.verify_session`)."""
    root = Path(data_root)
    seen: dict[tuple[int, int], Path] = {}

    def once(path: Path) -> None:
        try:
            info = os.stat(path)
        except FileNotFoundError:
            return
        key = (info.st_dev, info.st_ino)
        if key in seen:
            raise UserError(f"{path} is the same as {seen[key]} (one is a link to the other): the session would be "
                            "counted and loaded twice; remove the link", str(path))
        seen[key] = path

    studies: dict[str, list[SessionRecord]] = {}
    for study_dir in sorted(p for p in root.iterdir() if p.is_dir()) if root.is_dir() else []:
        once(study_dir)
        records = []
        for directory in sorted(p for p in study_dir.glob("sub-*/ses-*") if p.is_dir()):
            once(directory)
            for name in (dc.SESSION_METADATA_FILE, dc.TRIALS_FILE, dc.FRAMES_FILE):
                once(directory / name)
            record = session_record(directory, root)
            if record is not None:
                if verify and not record.unfinished:  # an unfinished one is listed as incomplete, with its fix
                    verify_session(directory)
                records.append(record)
        if records:
            studies[study_dir.name] = records
    return studies


def inventory(data_root: Path, *, verify: bool = True) -> dict[str, StudySessions]:
    """Every session under ``data_root/<study>/sub-*/ses-*/``, grouped by study.

    With ``verify`` (the default) each session's finalised files must match the SHA-256 its
    session.json recorded (:func:`psyop.finalised.verify_session`): a damaged or edited session is
    a :class:`UserError` naming it."""
    studies: dict[str, StudySessions] = {}
    for study, records in session_records(data_root, verify=verify).items():
        simulated = sum(1 for r in records if r.simulated is True)
        studies[study] = StudySessions(
            study, simulated, len(records) - simulated, sum(1 for r in records if not r.complete),
            tuple(r.participant for r in records),
            tuple(f"{r.directory.parent.name}/{r.directory.name}" for r in records if r.simulated is None),
            tuple(r.directory for r in records if r.unfinished))
    return studies


def check_not_mixed(studies: dict[str, StudySessions], data_root: Path) -> None:
    """UserError when a study pools simulated and real sessions."""
    mixed = [s for s in studies.values() if s.mixed]
    if mixed:
        names = "; ".join(s.describe() for s in mixed)
        raise UserError(f"simulated and real sessions mixed in one study ({names}): its figures would pool them. "
                        f"Move the simulated sessions out of {data_root}/ (they are marked \"simulated\": true in "
                        "session.json), or pool them on purpose with `make figures MIX=1` (psyop sessions --allow-mixed)",
                        str(data_root))
