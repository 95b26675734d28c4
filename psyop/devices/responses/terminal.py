"""Keys typed into the terminal ``psyop run`` was started from: answers (``--responses keyboard``) and the
experimenter's control keys (Escape, ``p``, ``c``: psyop.session.controls) for a session with no window.

The terminal is read when standard input is a terminal, ``psyop run``'s process group is its foreground one (a
session started in the background, or by a script with its input redirected, leaves it alone) and the session is
live (``--clock real``). While the session runs the terminal is in cbreak mode (each key arrives as typed, no echo;
Ctrl-C still sends SIGINT); its settings are restored when the session ends (:meth:`TerminalKeys.close`).

A reader thread waits on the terminal (``select``) and decodes what arrives: a printable character is its own name
in lower case (``y``, ``2``), Enter is ``enter``, the space bar ``space``, the arrow keys' escape sequences
(``ESC [ A`` .. ``ESC [ D`` and the ``ESC O`` forms) ``up``, ``down``, ``right``, ``left``, and a lone ESC byte (no
sequence following within :data:`ESCAPE_WAIT_S`) is Escape. Each press is stamped on the session clock as it is
decoded. Escape and the other control keys go to the session's controls (Escape interrupts the main thread as
Ctrl-C does); every other key is queued for :meth:`TerminalKeys.poll` (a
:class:`~psyop.devices.responses.keyboard.KeyEvents` source).

Escape's interrupt needs a Python handler for SIGINT. A process started as a background job (or by a harness
that ignores SIGINT) inherits SIGINT ignored, and an interrupt to an ignored signal does nothing: Escape would be
lost. So while the keys are read for a session's controls, an ignored SIGINT is handled as Python's default
(KeyboardInterrupt) and ignored again at :meth:`TerminalKeys.close`: the terminal is the foreground one, whose
Escape and Ctrl-C are the experimenter's way to stop.
"""

from __future__ import annotations

import os
import select
import signal
import sys
import threading
from typing import TYPE_CHECKING

from psyop.session.controls import ESCAPE_KEY, SessionControls

if TYPE_CHECKING:
    from psyop.session.clock import Clock

#: how long a lone ESC byte waits for the rest of an arrow key's sequence before it counts as Escape (s)
ESCAPE_WAIT_S = 0.05
#: the arrow keys' final bytes after ``ESC [`` or ``ESC O``
ARROWS = {"A": "up", "B": "down", "C": "right", "D": "left"}
SOURCE = "the terminal"


def terminal_usable(fd: int | None = None) -> bool:
    """Whether ``fd`` (standard input by default) is a terminal whose foreground process group is this process's."""
    if fd is None:
        try:
            fd = sys.stdin.fileno()
        except (AttributeError, ValueError, OSError):  # no stdin, or one without a descriptor (a test's capture)
            return False
    if not os.isatty(fd):
        return False
    try:
        return os.tcgetpgrp(fd) == os.getpgrp()
    except OSError:  # a terminal that is no process's controlling one
        return False


def _sigint_ignored() -> bool:
    """Whether this process ignores SIGINT (inherited, as a background job's child does); False off the main
    thread, where no handler can be set."""
    return threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGINT) == signal.SIG_IGN


def decode(data: str) -> list[str]:
    """Key names of the characters ``data`` holds (module docstring); a lone trailing ESC is Escape.

    Examples
    --------
    >>> decode("y\\x1b[D\\r \\x1b")
    ['y', 'left', 'enter', 'space', 'escape']
    """
    names: list[str] = []
    i = 0
    while i < len(data):
        char = data[i]
        if char == "\x1b":
            if data[i + 1:i + 2] in ("[", "O") and data[i + 2:i + 3]:
                names.append(ARROWS.get(data[i + 2], ""))
                i += 3
                continue
            names.append(ESCAPE_KEY)
        elif char in "\r\n":
            names.append("enter")
        elif char == " ":
            names.append("space")
        elif char.isprintable():
            names.append(char.lower())
        i += 1
    return [n for n in names if n]


class TerminalKeys:
    """The terminal's keys (module docstring): started on construction, stopped and restored by :meth:`close`."""

    def __init__(self, clock: Clock, controls: SessionControls | None = None, fd: int | None = None) -> None:
        import termios
        import tty

        self.fd = sys.stdin.fileno() if fd is None else fd
        self._clock = clock
        self.controls = controls
        self._keys: list[tuple[str, float]] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._saved = termios.tcgetattr(self.fd)
        self._sigint_ignored = controls is not None and _sigint_ignored()
        if self._sigint_ignored:  # Escape interrupts as Ctrl-C does (module docstring)
            signal.signal(signal.SIGINT, signal.default_int_handler)
        tty.setcbreak(self.fd, termios.TCSANOW)  # keys typed ahead of the session are kept
        self.presses = 0  # keys decoded (answers and controls)
        self._thread = threading.Thread(target=self._read, name="psyop-terminal-keys", daemon=True)
        self._thread.start()

    def _read(self) -> None:
        pending = ""
        while not self._stop.is_set():
            ready, _, _ = select.select([self.fd], [], [], ESCAPE_WAIT_S if pending else 0.1)
            if ready:
                try:
                    chunk = os.read(self.fd, 64)
                except OSError:  # the terminal went away (hung up): SIGHUP ends the session
                    return
                if not chunk:
                    return
                pending += chunk.decode("utf-8", errors="replace")
                if pending.endswith("\x1b") or pending.endswith(("\x1b[", "\x1bO")):
                    continue  # the rest of an arrow key's sequence may follow
            if pending:
                self._deliver(decode(pending))
                pending = ""

    def _deliver(self, names: list[str]) -> None:
        for name in names:
            self.presses += 1
            if name == ESCAPE_KEY:
                if self.controls is not None:
                    self.controls.escape(SOURCE)
                continue
            if self.controls is not None and self.controls.press(name, SOURCE):
                continue
            with self._lock:
                self._keys.append((name, self._clock.now_s()))

    def poll(self) -> list[tuple[str, float]]:
        """Every answer key typed since the last poll: (name, time on the session clock)."""
        with self._lock:
            keys, self._keys = self._keys, []
        return keys

    def close(self) -> None:
        """Stop reading and give the terminal its settings back."""
        import termios

        self._stop.set()
        self._thread.join(timeout=1.0)
        try:
            termios.tcsetattr(self.fd, termios.TCSADRAIN, self._saved)
        except (OSError, termios.error):  # the terminal is gone
            pass
        if self._sigint_ignored:
            signal.signal(signal.SIGINT, signal.SIG_IGN)


__all__ = ["TerminalKeys", "decode", "terminal_usable"]
