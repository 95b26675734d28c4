"""One writer per session: an exclusive advisory lock on ``<session dir>/.lock``.

``flock`` locks belong to the open file and are released by the kernel when the holder
exits (even on SIGKILL), so a crashed session never needs a manual unlock. The holder
writes its pid and host into the file so that a refused writer can say who holds it.
The lock is taken without waiting: a second ``psyop run`` (or ``psyop recover``) on the
same session is refused at once with exit code 2.
"""

from __future__ import annotations

import fcntl
import json
import os
import platform
import time
from dataclasses import dataclass
from pathlib import Path

from psyop.errors import UserError

# how long a refused writer waits for the holder's description to appear (see _read_holder)
HOLDER_WAIT_S = 1.0


@dataclass
class SessionInUse(UserError):
    """Another process holds the session's lock (``holder`` says who): a maintenance command
    (`psyop recover`, `psyop simulate`) leaves the session to it instead of failing."""

    holder: str = "another process"


class SessionLock:
    """Hold the session's lock from :meth:`acquire` until :meth:`release` (or process exit)."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self._fd: int | None = None

    @property
    def held(self) -> bool:
        return self._fd is not None

    def acquire(self, purpose: str = "run") -> None:
        """Take the lock now or raise :class:`UserError` naming the holder (exit code 2)."""
        if self._fd is not None:
            return
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0), 0o644)
        except OSError as exc:
            raise UserError(f"cannot create the session lock: {exc.strerror or exc}", str(self.path)) from exc
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _read_holder(fd)
            os.close(fd)
            raise SessionInUse(
                f"session is in use by {holder}; only one psyop process may write a session "
                "(wait for it to end, or use another --session)", str(self.path.parent), holder=holder) from None
        except OSError as exc:
            os.close(fd)
            raise UserError(f"cannot lock the session: {exc.strerror or exc}", str(self.path)) from exc
        info = json.dumps({"pid": os.getpid(), "host": platform.node(), "purpose": purpose}).encode()
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, info, 0)
        except OSError:
            pass  # the lock holds without the description (e.g. disk full)
        self._fd = fd

    def check_free(self) -> None:
        """Raise the same :class:`UserError` as :meth:`acquire` if another process holds the
        lock now; takes nothing (a shared probe) and creates nothing."""
        if self._fd is not None:
            return
        try:
            fd = os.open(self.path, os.O_RDONLY | os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0))
        except OSError:
            return  # no lock file yet (new session) or unreadable: acquire() decides
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _read_holder(fd)
            raise SessionInUse(
                f"session is in use by {holder}; only one psyop process may write a session "
                "(wait for it to end, or use another --session)", str(self.path.parent), holder=holder) from None
        except OSError:
            pass
        finally:
            os.close(fd)

    def release(self) -> None:
        if self._fd is None:
            return
        fd, self._fd = self._fd, None
        try:
            os.ftruncate(fd, 0)
        except OSError:
            pass
        os.close(fd)  # closing the last descriptor releases the flock

    def __enter__(self) -> SessionLock:
        self.acquire()
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def _read_holder(fd: int, wait_s: float = HOLDER_WAIT_S) -> str:
    """Who holds the lock, as the holder wrote it. A holder writes its description just after
    taking the lock and truncates it just before releasing, so an empty file is re-read (polling,
    up to ``wait_s``) before the holder is reported as unnamed."""
    deadline = time.monotonic() + wait_s
    while True:
        try:
            info = json.loads(os.pread(fd, 4096, 0).decode() or "{}")
            return f"pid {int(info['pid'])} on host {str(info['host'])[:100]!r} ({str(info.get('purpose', 'run'))[:20]})"
        except (OSError, ValueError, KeyError, TypeError):
            if time.monotonic() >= deadline:
                return "another process (it had not written its pid and host yet, or was releasing the lock)"
            time.sleep(0.01)
