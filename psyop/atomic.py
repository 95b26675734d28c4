"""The one rule for every file psyop and analysis/ write: never half-written, every error one line.

:func:`write_atomic` writes a new file next to the target (``.NAME.PID.tmp``, created with
``O_EXCL | O_NOFOLLOW``), fsyncs it, renames it over the target and fsyncs the folder, so a
crash, a full disk or an I/O error leaves either the old file or the new one, never a torn one.
:func:`fsync_dir` raises on a failed directory sync (the rename is not durable without it).
:func:`io_error` turns an ``OSError`` into a :class:`~psyop.errors.UserError` (exit code 2)
naming the file and the fix; the ``psyop`` command line and the analysis scripts use it for
any ``OSError`` that reaches them. Stdlib only: quick to import.
"""

from __future__ import annotations

import contextlib
import errno
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import BinaryIO

from psyop.errors import UserError

TEMP_SUFFIX = ".tmp"
#: directory fsync is not supported here (some network/FUSE file systems): nothing to make durable
_DIR_SYNC_UNSUPPORTED = {errno.EINVAL, getattr(errno, "ENOTSUP", errno.EINVAL), getattr(errno, "EOPNOTSUPP", errno.EINVAL)}

Content = bytes | str | Callable[[BinaryIO], object]


def temp_path(path: Path) -> Path:
    """The temporary name :func:`write_atomic` uses for ``path`` in this process."""
    return path.with_name(f".{path.name}.{os.getpid()}{TEMP_SUFFIX}")


@contextlib.contextmanager
def exclusive_temp(path: Path) -> Iterator[tuple[BinaryIO, Path]]:
    """A new temporary file next to ``path`` (O_EXCL | O_NOFOLLOW: never a planted file or
    symlink), removed again if the body does not rename it into place."""
    tmp = temp_path(Path(path))
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(tmp, flags, 0o644)
    except FileExistsError:  # a stale temp file (or a planted link) of a dead process with our pid
        tmp.unlink()
        fd = os.open(tmp, flags, 0o644)
    try:
        with os.fdopen(fd, "wb") as handle:
            yield handle, tmp
    finally:
        if os.path.lexists(tmp):
            tmp.unlink()


def stale_temp_files(directory: Path) -> list[Path]:
    """Temporary files left by an interrupted atomic write (``.NAME.PID.tmp``)."""
    if not Path(directory).is_dir():
        return []
    return sorted(p for p in Path(directory).iterdir() if p.name.startswith(".") and p.name.endswith(TEMP_SUFFIX))


def fsync_dir(directory: Path) -> None:
    """Make the entries of ``directory`` (a rename, a new file) durable; an error is raised
    (``OSError`` naming the folder), except where the file system cannot sync folders."""
    try:
        fd = os.open(directory, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror, str(directory)) from exc
    try:
        os.fsync(fd)
    except OSError as exc:
        if exc.errno not in _DIR_SYNC_UNSUPPORTED:
            raise OSError(exc.errno, exc.strerror, str(directory)) from exc
    finally:
        os.close(fd)


def write_atomic(path: Path, content: Content) -> Path:
    """Write ``content`` to ``path`` atomically and durably; return ``path``.

    ``content`` is bytes, text (UTF-8) or a function that writes to the binary handle it is
    given (``fig.savefig``, ``pq.write_table``). The folder is created. An ``OSError`` carries
    ``path`` as its ``filename`` (see :func:`io_error`); the old file, if any, is untouched.

    Examples
    --------
    >>> import tempfile
    >>> target = Path(tempfile.mkdtemp()) / "out" / "a.txt"
    >>> write_atomic(target, "hello\\n").read_text()
    'hello\\n'
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with exclusive_temp(path) as (handle, tmp):
            if callable(content):
                content(handle)
            else:
                handle.write(content.encode() if isinstance(content, str) else content)
            handle.flush()
            os.fsync(handle.fileno())
            os.replace(tmp, path)
        fsync_dir(path.parent)
    except OSError as exc:
        if exc.filename is not None:
            raise
        raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc
    return path


_FIXES = {
    errno.ENOSPC: "free space on that disk, then rerun the same command",
    errno.EDQUOT: "free space (or raise your disk quota), then rerun the same command",
    errno.EFBIG: "the file is over this system's file size limit (ulimit -f): raise it, then rerun the same command",
    errno.EIO: "the disk reported an I/O error: check the disk (dmesg), then rerun the same command",
    errno.EROFS: "the file system is read-only: point the command at a writable folder",
    errno.EACCES: "you have no permission there: fix the permissions or choose another folder",
    errno.EPERM: "you have no permission there: fix the permissions or choose another folder",
}


def io_error(exc: OSError, path: Path | str | None = None, fix: str | None = None) -> UserError:
    """A one-line :class:`UserError` (exit code 2) for ``exc``: the file, what failed, the fix.

    Examples
    --------
    >>> str(io_error(OSError(errno.ENOSPC, "No space left on device", "results/a.csv")))
    'results/a.csv: No space left on device; free space on that disk, then rerun the same command'
    """
    where = str(path) if path is not None else (str(exc.filename) if exc.filename is not None else None)
    reason = exc.strerror or str(exc) or type(exc).__name__
    advice = fix or _FIXES.get(exc.errno or -1, "fix the cause, then rerun the same command")
    return UserError(f"{reason}; {advice}", where)
