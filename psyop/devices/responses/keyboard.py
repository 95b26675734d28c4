"""Keyboard responses through a small event interface (a window supplies the events).

Keys per response kind: 2AFC interval '1'/'2' (or left/right arrows); near side
left/right arrows (or 'l'/'r'); preference '1'/'a' for the first and '2'/'b' for the
second stimulus; reach: 'space' confirms and the reach is read from the hand pose; NC nulling
'w' (or left) for with the eye, 'a' (or right) for against it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from psyop.session.rows import TrialRow
from psyop.session.responses.base import Response, ResponseKind, score

KEYMAPS: dict[ResponseKind, dict[str, str]] = {
    ResponseKind.TWO_INTERVAL: {"1": "1", "2": "2", "left": "1", "right": "2", "kp_1": "1", "kp_2": "2"},
    ResponseKind.NEAR_SIDE: {"left": "left", "right": "right", "l": "left", "r": "right"},
    ResponseKind.PREFERENCE: {"1": "a", "2": "b", "a": "a", "b": "b", "left": "a", "right": "b"},
    ResponseKind.REACH: {"space": "confirm", "enter": "confirm"},
    ResponseKind.WITH_AGAINST: {"w": "with", "a": "against", "left": "with", "right": "against"},
}


class KeyEvents(Protocol):
    """Source of key presses: ``poll`` returns (key name, time on the session clock) pairs."""

    def poll(self) -> list[tuple[str, float]]: ...


class KeyboardResponses:
    """Maps key presses to answers; ``collect`` returns None until a valid key arrives."""

    needs_images = True

    def __init__(self, events: KeyEvents, kind: ResponseKind, *, reach_m: Callable[[], float] | None = None) -> None:
        self.events = events
        self.kind = kind
        self.keymap = KEYMAPS[kind]
        self._reach_m = reach_m
        self._prompt_s: float | None = None
        self.early_presses = 0  # answer keys pressed before the response phase (ignored, never a negative time)

    def collect(self, row: TrialRow, now_s: float) -> Response | None:
        if self._prompt_s is None:
            self._prompt_s = now_s
        for key, t_s in self.events.poll():
            answer = self.keymap.get(key.lower())
            if answer is None:
                continue
            if t_s < self._prompt_s:  # pressed before the response phase began: not an answer to it
                self.early_presses += 1
                continue
            rt = t_s - self._prompt_s
            self._prompt_s = None
            if self.kind is ResponseKind.REACH:
                if self._reach_m is None:
                    raise RuntimeError("reach responses need a hand-pose source")
                reach = float(self._reach_m())
                r = score(self.kind, row, f"{reach:.6f}", reach_m=reach)
            else:
                r = score(self.kind, row, answer)
            return Response(r.response, r.correct, r.reach_m, r.chosen_mode, rt)
        return None

    def timed_out(self) -> None:
        self._prompt_s = None

    def close(self) -> None:
        return None
