"""session.json parsed: the one place psyop turns a session's session.json into a JSON object.

:func:`read_session_json` refuses, with one located :class:`~psyop.errors.UserError` naming the file and
the fix, anything that is not a regular file of at most :data:`MAX_SESSION_JSON_BYTES` (a FIFO would
block, a device never ends), undecodable or damaged JSON (with its line and column) and a document that
is not an object. Readers above the session layer take the typed record built on it
(``psyop.session.log.record.read_record_file``); psyop.finalised, below it, takes the object itself.
Stdlib only (``psyop sessions`` and ``--help`` stay quick).
"""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

from psyop.errors import UserError
from psyop.records import JsonObject

__all__ = ["MAX_SESSION_JSON_BYTES", "SESSION_JSON_FIX", "read_session_json"]

#: session.json holds the protocol text and per-run records: a few hundred kB at most
MAX_SESSION_JSON_BYTES = 64 << 20
#: what to do about a damaged session.json (the trials are in the checksummed log either way)
SESSION_JSON_FIX = ("restore it from a backup, or delete it: `psyop recover` / `psyop run` then rebuild it from "
                    "the checksummed log")


def _kind(mode: int) -> str:
    """What a file that is not a regular one is, for the message ('' when none of these)."""
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe), "
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device, "
    return "a folder, " if stat.S_ISDIR(mode) else ""


def _read_regular(path: Path) -> bytes | None:
    """The bytes of ``path`` (None if absent), a regular file within the limit, else a UserError."""
    try:
        info = os.stat(path)
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise UserError(f"cannot read session.json: {exc.strerror or exc}", str(path)) from exc
    if not stat.S_ISREG(info.st_mode):
        raise UserError(f"session.json is {_kind(info.st_mode)}not a regular file; {SESSION_JSON_FIX}", str(path))
    if info.st_size > MAX_SESSION_JSON_BYTES:
        raise UserError(f"session.json is {info.st_size} bytes, over the {MAX_SESSION_JSON_BYTES} byte limit (a "
                        f"session.json is a few tens of kB); {SESSION_JSON_FIX}", str(path))
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
        with os.fdopen(fd, "rb") as handle:
            if not stat.S_ISREG(os.fstat(handle.fileno()).st_mode):  # swapped after the stat
                raise UserError(f"session.json is not a regular file; {SESSION_JSON_FIX}", str(path))
            raw = handle.read(MAX_SESSION_JSON_BYTES + 1)
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise UserError(f"cannot read session.json: {exc.strerror or exc}", str(path)) from exc
    if len(raw) > MAX_SESSION_JSON_BYTES:
        raise UserError(f"session.json is over the {MAX_SESSION_JSON_BYTES} byte limit; {SESSION_JSON_FIX}",
                        str(path))
    return raw


def read_session_json(path: Path) -> JsonObject | None:
    """The session.json at ``path`` as a dict; None if there is none. Anything else that is not a JSON
    object is a UserError naming the file (and the line and column of a JSON error).

    Examples
    --------
    >>> import tempfile
    >>> meta = Path(tempfile.mkdtemp()) / "session.json"
    >>> read_session_json(meta) is None
    True
    >>> _ = meta.write_text('{"seed": 7}')
    >>> read_session_json(meta)
    {'seed': 7}
    """
    raw = _read_regular(Path(path))
    if raw is None:
        return None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise UserError(f"session.json is damaged (not UTF-8 text: {exc.reason} at byte {exc.start}); "
                        f"{SESSION_JSON_FIX}", str(path)) from None
    try:
        meta = json.loads(text)
    except json.JSONDecodeError as exc:
        raise UserError(f"session.json is damaged ({exc.msg}); {SESSION_JSON_FIX}",
                        f"{path}:{exc.lineno}:{exc.colno}") from None
    if not isinstance(meta, dict):
        raise UserError(f"session.json is not a JSON object; {SESSION_JSON_FIX}", str(path))
    return meta
