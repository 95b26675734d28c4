"""Signals that stop a session: SIGTERM and SIGHUP act like Ctrl-C; writes that must finish hold them.

``psyop run`` wraps the session in :func:`stop_signals_as_interrupt`: SIGTERM (``kill``, a
system shutdown) and SIGHUP (the terminal closed) are handed to whatever SIGINT handler is
installed at that moment, so they end the session exactly as Ctrl-C does (the trial in
progress is discarded, the log is finalised 'incomplete', the session resumes), and a signal
that arrives while a trial record or the finalised files are written waits for the write.
:func:`interrupts_deferred` is that wait. Only the main thread handles signals; elsewhere
both are no-ops.
"""

from __future__ import annotations

import _signal  # type: ignore[import-not-found]  # C module behind signal.signal (no typeshed stub)
import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType, TracebackType

#: the signals that end a session like Ctrl-C
STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGHUP") if hasattr(signal, name))


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


@contextlib.contextmanager
def stop_signals_as_interrupt() -> Iterator[list[int]]:
    """While active, SIGTERM and SIGHUP are handled as SIGINT; yields the signals received.

    Examples
    --------
    >>> import os
    >>> with stop_signals_as_interrupt() as received:
    ...     try:
    ...         os.kill(os.getpid(), signal.SIGTERM)
    ...     except KeyboardInterrupt:
    ...         pass
    >>> [signal.Signals(s).name for s in received]
    ['SIGTERM']
    """
    received: list[int] = []
    if not _main_thread():
        yield received
        return

    def forward(signum: int, frame: FrameType | None) -> None:
        received.append(signum)
        handler = signal.getsignal(signal.SIGINT)
        if callable(handler):  # Python's default (raises KeyboardInterrupt) or a write's deferral
            handler(signal.SIGINT, frame)
        else:  # SIG_IGN (a background job ignores Ctrl-C, not a kill), SIG_DFL, or set from C
            raise KeyboardInterrupt

    previous = {signum: signal.signal(signum, forward) for signum in STOP_SIGNALS}
    try:
        yield received
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def interrupts_deferred() -> _Deferral:
    """Hold SIGINT (and, under :func:`stop_signals_as_interrupt`, SIGTERM/SIGHUP) until the
    block ends, then raise KeyboardInterrupt: a write that must not be torn finishes first.
    An exception raised in the block propagates as it is (the held signal is dropped with it).

    Examples
    --------
    >>> import os
    >>> done = []
    >>> try:
    ...     with interrupts_deferred():
    ...         os.kill(os.getpid(), signal.SIGINT)
    ...         done.append("written")
    ... except KeyboardInterrupt:
    ...     done.append("interrupted")
    >>> done
    ['written', 'interrupted']
    """
    return _Deferral()


class _Deferral:
    """The context manager of :func:`interrupts_deferred`: a plain class over the C-level ``_signal.signal``
    (the session loop enters one per trial; the generator-based context manager and ``signal.signal``'s enum
    conversions were 4 % of a simulated replication). Off the main thread it does nothing."""

    __slots__ = ("_previous", "_received", "_active")

    def __init__(self) -> None:
        self._received: list[int] = []
        self._previous: object = None
        self._active = False

    def _hold(self, signum: int, frame: FrameType | None) -> None:
        self._received.append(signum)

    def __enter__(self) -> None:
        if _main_thread():
            self._previous = _signal.signal(_signal.SIGINT, self._hold)
            self._active = True

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 traceback: TracebackType | None) -> None:
        if not self._active:
            return
        self._active = False
        _signal.signal(_signal.SIGINT, self._previous)
        if exc_type is None and self._received:
            raise KeyboardInterrupt
