"""Reading a file the user names (a protocol, a replayed session's logs) with bounded memory.

:class:`InputFile` refuses anything that is not a regular file (a FIFO would block forever, a
device such as ``/dev/zero`` never ends) from ``stat`` before opening it, refuses files over
its size limit, and re-checks the opened descriptor (a file swapped after the ``stat``); every
refusal is a :class:`~psyop.errors.UserError` naming the path.
"""

from __future__ import annotations

import os
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from psyop.errors import UserError

if TYPE_CHECKING:
    import pandas as pd


def _kind(mode: int) -> str:
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    return "not a regular file"


@dataclass(frozen=True)
class InputFile:
    """What a file is for, in messages, and its size limit.

    ``what``: e.g. "the protocol file"; ``give``: the fix, e.g. "give a protocol .yaml file";
    ``typical``: what a real one weighs; ``not_found``: the message for a missing path
    (``{path}`` is filled in)."""

    what: str
    give: str
    max_bytes: int
    typical: str
    not_found: str

    def check(self, path: Path) -> int:
        """The size of ``path`` in bytes if it is a regular file within the limit, else a UserError."""
        try:
            info = os.stat(path)
        except FileNotFoundError:
            raise UserError(self.not_found.format(path=path)) from None
        except OSError as error:
            raise UserError(f"cannot read {path}: {error.strerror}") from None
        if stat.S_ISDIR(info.st_mode):
            raise UserError(f"{path} is a folder; {self.give}")
        if not stat.S_ISREG(info.st_mode):
            raise UserError(f"{path} is {_kind(info.st_mode)}; {self.give}", str(path))
        if info.st_size > self.max_bytes:
            raise UserError(f"{self.what} is {info.st_size} bytes, over the {self.max_bytes} byte limit; "
                            f"{self.typical}", str(path))
        return int(info.st_size)

    def read_bytes(self, path: Path) -> bytes:
        """The bytes of ``path`` after :meth:`check` (never more than ``max_bytes``)."""
        self.check(path)
        try:
            fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
            with os.fdopen(fd, "rb") as handle:
                if not stat.S_ISREG(os.fstat(handle.fileno()).st_mode):  # swapped after the stat
                    raise UserError(f"{path} is not a regular file; {self.give}", str(path))
                raw = handle.read(self.max_bytes + 1)
        except OSError as error:
            raise UserError(f"cannot read {path}: {error.strerror}") from None
        if len(raw) > self.max_bytes:
            raise UserError(f"{self.what} is over the {self.max_bytes} byte limit", str(path))
        return raw


#: the largest logged table a replay reads: an hour at 90 Hz is ~330k frame rows, tens of MB
MAX_LOG_TABLE_BYTES = 512 << 20


def read_logged_table(path: Path, context: str) -> pd.DataFrame:  # pandas imported lazily inside
    """A session's ``frames.parquet``/``trials.parquet`` named for a replay (``context``, e.g.
    "--tracker replay"): a regular parquet file within :data:`MAX_LOG_TABLE_BYTES`, else a UserError."""
    import io

    import pandas as pd

    table_file = InputFile(
        what=f"{context}: {path.name}", give=f"{context} needs a finished session's {path.name}",
        max_bytes=MAX_LOG_TABLE_BYTES, typical="a psyop session log is tens of MB; is this the right file?",
        not_found=f"{context}: no file {{path}}")
    raw = table_file.read_bytes(path)
    try:
        return pd.read_parquet(io.BytesIO(raw))
    except Exception as exc:  # noqa: BLE001 - any unreadable file is the user's input
        raise UserError(f"{context}: not a parquet table ({type(exc).__name__}: {exc}); give a session's "
                        f"{path.name} (run `psyop recover` on a crashed session first)", str(path)) from None
