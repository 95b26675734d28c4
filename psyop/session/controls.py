"""The experimenter's keys during a session: Escape ends it, ``p`` pauses and resumes it, ``c`` asks for a
recalibration at the next trial boundary.

Every key source of a live session (the session window, the experimenter window, the terminal psyop run was
started from: psyop.devices) hands each key press to :meth:`SessionControls.press` first; a control key is taken
there (and never reaches the response source), any other key goes on to the source's queue. A key the session's
key map gives an answer to (``response.inputs.keys``, or the kind's own keys, with ``--responses keyboard``) stays
an answer: its control is then not available in that session, which :meth:`SessionControls.unavailable` names
(the runner prints it at the start).

What the keys do (psyop.session.loop acts on them):

- Escape: the session ends as on Ctrl-C (exit 130, the trial in progress discarded, the session resumable). The
  windows raise :class:`EscapePressed` from their next event pump; the terminal's reader thread interrupts the main
  thread as Ctrl-C does (:func:`_thread.interrupt_main`), so a record being written is finished first
  (psyop.session.signals.interrupts_deferred). ``stop_reason`` says where Escape was pressed.
- ``p``: a pause between trials. The trial in progress runs on to its end and is recorded; at the next trial
  boundary the session waits (the display shows no stimulus) until ``p`` is pressed again. ``p`` pressed twice
  before the boundary is no pause. The pause is logged in events.parquet (screen ``pause``: start, end, duration,
  the key's source) and never advances a virtual clock.
- ``c``: at the next trial boundary the loop runs its recalibration hooks and the protocol's gaze validation
  (``gaze_validation:``), logged in validation.parquet (when ``recalibrate``) and events.parquet (screen
  ``recalibrate``); without either, the key says so once, on the console and in events.parquet.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

#: the control keys, by the name the key sources queue them under (psyop.devices.window.key_name)
ESCAPE_KEY, PAUSE_KEY, RECALIBRATE_KEY = "escape", "p", "c"
CONTROL_KEYS = (ESCAPE_KEY, PAUSE_KEY, RECALIBRATE_KEY)


class EscapePressed(KeyboardInterrupt):
    """Escape was pressed in a window of the session: the session ends as on Ctrl-C (psyop.session.loop)."""


@dataclass
class SessionControls:
    """The control keys' state for one run (module docstring). ``answer_keys``: the keys that answer in this
    session (they are no controls); ``pumps``: each window's event pump (the loop calls them while paused, so
    their keys still arrive); ``interrupt``: how a source on another thread stops the main one (Ctrl-C's way)."""

    answer_keys: frozenset[str] = frozenset()
    pumps: list[Callable[[], None]] = field(default_factory=list)
    interrupt: Callable[[], None] | None = None
    pause_wanted: bool = False
    pause_source: str = ""
    recalibrate_wanted: bool = False
    recalibrate_source: str = ""
    stop_reason: str = ""
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def takes(self, key: str) -> bool:
        """Whether ``key`` is a control key in this session (not an answer)."""
        return key in CONTROL_KEYS and key not in self.answer_keys

    def unavailable(self) -> list[str]:
        """The control keys the key map gives answers to (their controls are off in this session)."""
        return [k for k in CONTROL_KEYS if k in self.answer_keys]

    def press(self, key: str, source: str) -> bool:
        """Handle a key pressed in ``source`` ('the terminal', 'the session window', ...); True when it was a
        control key (taken: not an answer). Escape only records where it came from: the caller raises."""
        if not self.takes(key):
            return False
        with self._lock:
            if key == ESCAPE_KEY:
                self.stop_reason = f"Escape pressed in {source}"
            elif key == PAUSE_KEY:
                self.pause_wanted = not self.pause_wanted
                self.pause_source = source
            else:
                self.recalibrate_wanted = True
                self.recalibrate_source = source
        return True

    def take_recalibrate(self) -> str | None:
        """Where ``c`` was pressed when it was since the last call, else None (the request is consumed)."""
        with self._lock:
            if not self.recalibrate_wanted:
                return None
            self.recalibrate_wanted = False
            return self.recalibrate_source or "a key"

    def pump(self) -> None:
        """Deliver every window's pending key presses (a window raises EscapePressed on Escape)."""
        for pump in self.pumps:
            pump()

    def escape(self, source: str) -> None:
        """Escape from a key source on another thread: note it and interrupt the main thread as Ctrl-C does."""
        self.press(ESCAPE_KEY, source)
        if self.interrupt is not None:
            self.interrupt()


def controls_for(answer_keys: Iterable[str]) -> SessionControls:
    """The controls of a session whose key map answers with ``answer_keys`` (lower case)."""
    import _thread

    return SessionControls(answer_keys=frozenset(k.lower() for k in answer_keys), interrupt=_thread.interrupt_main)


__all__ = ["CONTROL_KEYS", "ESCAPE_KEY", "EscapePressed", "PAUSE_KEY", "RECALIBRATE_KEY", "SessionControls",
           "controls_for"]
