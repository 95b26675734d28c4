"""The response record and the interface every response source implements; a response is scored by its kind
(psyop.protocol.kinds), which the session plan carries."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from psyop.protocol.kinds.base import ResponseKindSpec
from psyop.session.rows import TrialRow

__all__ = ["Response", "ResponseKindSpec", "ResponseSource", "score"]


@dataclass(frozen=True)
class Response:
    """One trial's answer. ``response`` is the raw answer as text ('1', 'left', 'a', '0.512')."""

    response: str
    correct: bool | None = None
    reach_m: float | None = None
    chosen_mode: str | None = None
    response_time_s: float = math.nan
    extras: tuple[tuple[str, float], ...] = ()  # extra trial-log values, e.g. hand position


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
