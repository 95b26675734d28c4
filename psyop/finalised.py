"""The finalised files of a session and their SHA-256: record at finalisation, verify before use.

``psyop run`` / ``psyop recover`` finalise a session by writing ``trials.parquet`` and
``frames.parquet`` (and any other finalised file, e.g. a raw gaze stream) from the checksummed
log. :func:`record_finalised` then records, in session.json under ``finalised_files``, the
SHA-256 and size of each. Every reader of finalised data (``load_dataset``, ``psyop sessions``,
``psyop export``, hence ``make figures``) calls :func:`verify_session` first: a flipped byte or
a re-written value (valid parquet, different content) changes the hash, and the session is
refused with one line naming it (:class:`psyop.errors.UserError`, exit code 2).

A deliberate edit is accepted only through :func:`reseal` (``psyop reseal SESSION --reason``),
which records the reason, the time and each file's old and new hash in session.json's
``reseals`` list, so the edit stays visible to anyone reading the session.

Stdlib only (``psyop sessions`` imports it and stays quick).
"""

from __future__ import annotations

import datetime as dt
import hashlib
import os
import stat
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from psyop.errors import UserError
from psyop.records import JsonMapping, JsonObject
from psyop.session_json import read_session_json

#: session.json key: ``{file name: {"sha256": hex, "size_bytes": int}}`` of every finalised file.
FINALISED_KEY = "finalised_files"
#: session.json key: the list of recorded deliberate edits (see :func:`reseal`).
RESEALS_KEY = "reseals"
#: Files in a session directory with these suffixes are finalised data and must be recorded.
FINALISED_SUFFIXES: tuple[str, ...] = (".parquet",)
SESSION_METADATA_FILE = "session.json"
_CHUNK_BYTES = 1 << 20


def sha256_file(path: Path) -> str:
    """The SHA-256 of a file's bytes, as lowercase hex.

    Examples
    --------
    >>> import tempfile
    >>> p = Path(tempfile.mkdtemp()) / "x"
    >>> _ = p.write_bytes(b"abc")
    >>> sha256_file(p)[:16]
    'ba7816bf8f01cfea'
    """
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for chunk in iter(lambda: handle.read(_CHUNK_BYTES), b""):
            digest.update(chunk)
    return digest.hexdigest()


def file_record(path: Path) -> JsonObject:
    """``{"sha256": ..., "size_bytes": ...}`` of one file."""
    return {"sha256": sha256_file(path), "size_bytes": int(os.stat(path).st_size)}


def record_finalised(meta: JsonObject, directory: Path, files: Iterable[Path]) -> JsonObject:
    """Record the SHA-256 of each finalised file of ``directory`` into ``meta`` (session.json).

    ``files`` are the files finalisation just wrote (paths inside ``directory``); earlier
    records of other files are kept only while those files still exist. Returns the record.

    Examples
    --------
    >>> import json, tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> _ = (d / "trials.parquet").write_bytes(b"PAR1")
    >>> meta = {}
    >>> sorted(record_finalised(meta, d, [d / "trials.parquet"]))
    ['trials.parquet']
    """
    directory = Path(directory)
    stored = meta.get(FINALISED_KEY)
    previous: JsonObject = stored if isinstance(stored, dict) else {}
    record: JsonObject = {name: value for name, value in previous.items() if (directory / name).is_file()}
    for path in files:
        record[Path(path).relative_to(directory).as_posix()] = file_record(Path(path))
    meta[FINALISED_KEY] = dict(sorted(record.items()))
    return meta[FINALISED_KEY]


@dataclass(frozen=True)
class FileProblem:
    """One finalised file that does not prove it is intact."""

    name: str
    #: 'changed' (hash differs), 'missing' (recorded, gone), 'unrecorded' (present, no hash)
    kind: str
    recorded_sha256: str | None
    found_sha256: str | None

    def describe(self) -> str:
        if self.kind == "changed":
            return (f"{self.name} does not match the SHA-256 recorded when the session was finalised "
                    f"(damaged or edited since: recorded {(self.recorded_sha256 or '')[:12]}..., now "
                    f"{(self.found_sha256 or '')[:12]}...)")
        if self.kind == "missing":
            return f"{self.name} is recorded as finalised but missing"
        return f"{self.name} has no SHA-256 in session.json (finalised by an older psyop, or written by hand)"


def finalised_candidates(directory: Path) -> list[str]:
    """Names of the finalised-data files present in a session directory (``*.parquet``)."""
    directory = Path(directory)
    if not directory.is_dir():
        return []
    return sorted(p.name for p in directory.iterdir()
                  if p.suffix in FINALISED_SUFFIXES and not p.name.startswith(".") and p.is_file())


def check_finalised(meta: JsonMapping, directory: Path) -> list[FileProblem]:
    """Every finalised file of ``directory`` that fails: hash differs, recorded file missing, or a
    data file present without a record. Empty when the session proves it is intact."""
    directory = Path(directory)
    raw = meta.get(FINALISED_KEY)
    recorded: JsonMapping = raw if isinstance(raw, Mapping) else {}
    problems: list[FileProblem] = []
    for name, entry in sorted(recorded.items()):
        want = entry.get("sha256") if isinstance(entry, Mapping) else None
        path = directory / name
        if not path.is_file():
            problems.append(FileProblem(name, "missing", want, None))
            continue
        if not stat.S_ISREG(os.stat(path).st_mode):
            problems.append(FileProblem(name, "changed", want, None))
            continue
        found = sha256_file(path)
        if found != want:
            problems.append(FileProblem(name, "changed", want, found))
    for name in finalised_candidates(directory):
        if name not in recorded:
            problems.append(FileProblem(name, "unrecorded", None, None))
    return problems


#: session.json statuses of a session that never reached 'complete': a run in progress (or killed), a
#: resumable one; its parquet files are rebuilt from the log by the next finalisation anyway
UNFINISHED_STATUSES = ("running", "incomplete")


def finalisation_interrupted(meta: JsonMapping, directory: Path) -> bool:
    """True when a session's parquet files are not sealed because a finalisation did not finish:
    the last run ended after the last finalisation (:func:`unfinished_finalisation`), or the session
    never reached 'complete' (:data:`UNFINISHED_STATUSES`) and its parquet files do not match session.json (a run, or a `psyop
    recover` of a killed run, killed between writing them and recording their SHA-256). Every recorded
    trial is in the checksummed log either way, and `psyop recover` finishes the session."""
    if unfinished_finalisation(meta):
        return True
    return meta.get("status") in UNFINISHED_STATUSES and bool(check_finalised(meta, directory))


def unfinished_finalisation(meta: JsonMapping) -> bool:
    """True when session.json says the last run ended but its finalisation never finished (the
    process was killed while the parquet files were being written): ``runs[-1].ended`` is set and
    ``finalised`` is missing or older. ``psyop recover`` finishes such a session from its log.

    Examples
    --------
    >>> unfinished_finalisation({"runs": [{"ended": "2026-12-02T09:00:05+00:00"}]})
    True
    >>> unfinished_finalisation({"runs": [{"ended": "2026-12-02T09:00:05+00:00"}],
    ...                          "finalised": "2026-12-02T09:00:06+00:00"})
    False
    """
    runs = meta.get("runs")
    last = runs[-1] if isinstance(runs, list) and runs and isinstance(runs[-1], Mapping) else None
    ended = last.get("ended") if last is not None else None
    if not isinstance(ended, str):
        return False
    finalised = meta.get("finalised")
    if not isinstance(finalised, str):
        return True
    try:
        return dt.datetime.fromisoformat(finalised) < dt.datetime.fromisoformat(ended)
    except ValueError:
        return False


def read_session_meta(directory: Path) -> JsonObject | None:
    """A session directory's session.json as a dict (None when absent); unreadable: a UserError naming it
    (:func:`psyop.session_json.read_session_json`, the one parser of session.json)."""
    return read_session_json(Path(directory) / SESSION_METADATA_FILE)


def verify_session(directory: Path) -> None:
    """Refuse a session whose finalised files do not match session.json's SHA-256 records.

    One :class:`UserError` (exit code 2) naming the session directory and the first file that
    fails, with the two ways out: rebuild from the checksummed log, or record a deliberate edit.

    Examples
    --------
    >>> import json, tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> _ = (d / "trials.parquet").write_bytes(b"PAR1")
    >>> meta = {}
    >>> _ = record_finalised(meta, d, [d / "trials.parquet"])
    >>> _ = (d / "session.json").write_text(json.dumps(meta))
    >>> verify_session(d)
    >>> _ = (d / "trials.parquet").write_bytes(b"PAR2")
    >>> verify_session(d)
    Traceback (most recent call last):
    ...
    psyop.errors.UserError: ...trials.parquet does not match the SHA-256 recorded...
    """
    directory = Path(directory)
    meta = read_session_meta(directory)
    if meta is None:
        if finalised_candidates(directory):
            raise UserError("finalised files without a session.json: nothing proves they are intact; "
                            "run `psyop recover` on this session to rebuild them from its log", str(directory))
        return
    problems = check_finalised(meta, directory)
    if not problems:
        return
    if unfinished_finalisation(meta) or meta.get("status") in UNFINISHED_STATUSES:  # finalisation_interrupted
        raise UserError(
            "this session's finalisation was interrupted before it finished (its parquet files are not all "
            f"written and sealed); every recorded trial is in its checksummed log: run `psyop recover {directory}` "
            "to finish it", str(directory))
    more = f" (and {len(problems) - 1} more file(s))" if len(problems) > 1 else ""
    raise UserError(
        f"session refused: {problems[0].describe()}{more}. Restore the file, or delete it and run "
        f"`psyop recover {directory}` to rebuild it from the checksummed log; for a deliberate edit, "
        f"record it with `psyop reseal {directory} --reason TEXT`", str(directory))


def reseal(meta: JsonObject, directory: Path, reason: str) -> JsonObject:
    """Record a deliberate edit in ``meta`` (session.json's content): new hashes for every finalised
    file, and the reason, time and each changed file's old and new hash appended to ``reseals``.
    Returns the appended record; the caller writes ``meta`` back (atomically) under the session lock
    (``psyop reseal`` does).

    Refused (:class:`UserError`) when the reason is blank or every file is already intact.

    Examples
    --------
    >>> import json, tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> _ = (d / "trials.parquet").write_bytes(b"PAR1")
    >>> meta = {}
    >>> _ = record_finalised(meta, d, [d / "trials.parquet"])
    >>> _ = (d / "trials.parquet").write_bytes(b"PAR2")
    >>> reseal(meta, d, "fixed a typo in a condition label")["files"]["trials.parquet"]["change"]
    'changed'
    >>> check_finalised(meta, d)
    []
    """
    directory = Path(directory)
    if not reason or not reason.strip():
        raise UserError("a reseal needs a reason (--reason TEXT): it is recorded in session.json", "--reason")
    problems = check_finalised(meta, directory)
    if not problems:
        raise UserError("every finalised file matches its recorded SHA-256: nothing to reseal", str(directory))
    changes: JsonObject = {}
    for problem in problems:
        found = None if problem.kind == "missing" else sha256_file(directory / problem.name)
        changes[problem.name] = {"change": problem.kind, "old_sha256": problem.recorded_sha256, "new_sha256": found}
    record = {"at": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"), "reason": reason.strip(),
              "files": changes}
    meta[FINALISED_KEY] = {}
    record_finalised(meta, directory, [directory / name for name in finalised_candidates(directory)])
    meta.setdefault(RESEALS_KEY, []).append(record)
    return record
