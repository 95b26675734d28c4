"""The response record and the interface every response source implements."""

from __future__ import annotations

from psyop.session.rows import TrialRow

import math
from dataclasses import dataclass
from enum import Enum
from typing import Protocol


class ResponseKind(str, Enum):
    """What a trial asks for, decided from the schedule's columns (architecture contract)."""

    TWO_INTERVAL = "2afc_interval"  # '1' or '2'
    NEAR_SIDE = "near_side"  # 'left' or 'right'
    PREFERENCE = "preference"  # 'a' or 'b'
    REACH = "reach"  # a distance in metres
    WITH_AGAINST = "with_against"  # 'with' or 'against' (NC nulling)


def response_kind(columns: set[str] | list[str]) -> ResponseKind:
    cols = set(columns)
    if "correct_interval" in cols:
        return ResponseKind.TWO_INTERVAL
    if "near_side" in cols:
        return ResponseKind.NEAR_SIDE
    if {"mode_a", "mode_b"} <= cols:
        return ResponseKind.PREFERENCE
    if "target_fraction" in cols:
        return ResponseKind.REACH
    if "rendered_nc_mm" in cols:
        return ResponseKind.WITH_AGAINST
    raise ValueError(
        "cannot tell the response type from the schedule: expected one of the columns "
        "correct_interval, near_side, mode_a/mode_b, target_fraction or rendered_nc_mm"
    )


@dataclass(frozen=True)
class Response:
    """One trial's answer. ``response`` is the raw answer as text ('1', 'left', 'a', '0.512')."""

    response: str
    correct: bool | None = None
    reach_m: float | None = None
    chosen_mode: str | None = None
    response_time_s: float = math.nan
    extras: tuple[tuple[str, float], ...] = ()  # extra trial-log values, e.g. hand position


def score(kind: ResponseKind, row: TrialRow, answer: str, reach_m: float | None = None) -> Response:
    """Fill ``correct`` / ``chosen_mode`` / ``reach_m`` from a raw answer."""
    if kind is ResponseKind.TWO_INTERVAL:
        return Response(answer, correct=answer == str(int(row["correct_interval"])))
    if kind is ResponseKind.NEAR_SIDE:
        return Response(answer, correct=answer == str(row["near_side"]))
    if kind is ResponseKind.PREFERENCE:
        chosen = str(row["mode_a"] if answer == "a" else row["mode_b"])
        return Response(answer, chosen_mode=chosen)
    return Response(answer, reach_m=reach_m)


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
