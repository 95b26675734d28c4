"""Trial events the session announces to outside recorders (LSL markers, Pupil annotations).

The loop emits one :class:`SessionEvent` per trial start, phase onset (the response phase
included), response and recorded trial end; each :class:`EventSink` passes it on (an LSL marker
outlet, Pupil Capture's annotation plugin). ``t_s`` is on the session clock; a sink maps it onto
its own clock. A trial the session discards (interrupted, tracker lost) has a ``trial_start`` and
no ``trial_end``: ``trial_end`` is emitted only once the trial is durable in the log. A trial the protocol's ``timing:``
rule discards (psyop.protocol.timing) is told with a ``timing_rerun`` event, its value the reason. Each
target of a gaze validation (psyop.session.validation) is a ``phase`` event of trial -1, condition
``gaze_validation``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Protocol

EventKind = Literal["trial_start", "phase", "response", "trial_end", "timing_rerun"]


@dataclass(frozen=True)
class SessionEvent:
    """One event: ``kind``; the trial (index and condition); when (session clock); ``value``: the
    phase name (``phase``), the raw answer (``response``, ``timeout`` when none came) or why the trial is
    run again (``timing_rerun``);
    ``duration_s``: the trial's duration (``trial_end``), else 0."""

    kind: EventKind
    trial: int
    condition: str
    t_s: float
    value: str = ""
    duration_s: float = 0.0


class EventSink(Protocol):
    """Where session events go; ``emit`` must not block the loop for long (a network send)."""

    def emit(self, event: SessionEvent) -> None: ...

    def close(self) -> None: ...
