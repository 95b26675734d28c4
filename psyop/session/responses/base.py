"""The response record and the interface every response source implements; a response is scored by its kind
(psyop.protocol.kinds), which the session plan carries."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from psyop.protocol.kinds.base import ResponseKindSpec
from psyop.session.rows import TrialRow

__all__ = ["RawInput", "RawInputSource", "Response", "ResponseKindSpec", "ResponseSource", "score"]


@dataclass(frozen=True)
class Response:
    """One trial's answer. ``response`` is the raw answer as text ('1', 'left', 'a', '0.512')."""

    response: str
    correct: bool | None = None
    reach_m: float | None = None
    chosen_mode: str | None = None
    response_time_s: float = math.nan
    extras: tuple[tuple[str, float | str], ...] = ()  # extra trial-log values, e.g. hand position, a path


def score(kind: ResponseKindSpec, row: TrialRow, answer: str, reach_m: float | None = None) -> Response:
    """The response ``answer`` (a value of the kind's key map, or a reach's distance as text) scored by its kind."""
    scored = kind.score(row, answer)
    return Response(answer, correct=scored.correct, reach_m=reach_m, chosen_mode=scored.chosen_mode)


class ResponseSource(Protocol):
    """Collects the response to one trial.

    ``needs_images`` says whether the source must see rendered frames (a person does;
    most simulated observers do not, so headless simulated sessions skip rendering).
    ``collect`` may block (a person answering) or return at once (simulated).
    """

    needs_images: bool

    def collect(self, row: TrialRow, now_s: float) -> Response | None: ...

    def timed_out(self) -> None:
        """The response phase ended without an answer (the plan's ``timeout_s``): forget this
        trial's prompt time so that the next trial's response time starts afresh."""
        ...

    def close(self) -> None: ...


@dataclass(frozen=True)
class RawInput:
    """One raw input of a device, already named by the response kind's map (an adjustment's 'up', 'down',
    'confirm'; 'axis' for a thumbstick, whose deflection in [-1, 1] is ``amount``), at its session-clock time."""

    name: str
    t_s: float
    amount: float = 1.0


@runtime_checkable
class RawInputSource(Protocol):
    """A response source that can report every raw input, not only an answer: what a response that the loop
    builds from many inputs (an adjustment) reads, once per frame. Inputs before ``since_s`` (the response
    phase's start) are dropped (pressed before the prompt); each input is reported once."""

    def raw_inputs(self, since_s: float, now_s: float) -> list[RawInput]: ...
