"""Keyboard responses through a small event interface (a window supplies the events).

The keys are raw input; the response kind (psyop.protocol.kinds, carried by the session plan) maps each to
an answer (its ``keys``) and scores it. A kind whose answer is a hand position (reach) has its keys confirm
and the reach read from the hand pose. docs/protocols.md lists each kind's keys.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Protocol

from psyop.session.rows import TrialRow
from psyop.session.responses.base import Response, ResponseKindSpec, score

class KeyEvents(Protocol):
    """Source of key presses: ``poll`` returns (key name, time on the session clock) pairs."""

    def poll(self) -> list[tuple[str, float]]: ...


class KeyboardResponses:
    """Maps key presses to answers; ``collect`` returns None until a valid key arrives."""

    needs_images = True

    def __init__(self, events: KeyEvents, kind: ResponseKindSpec, *, reach_m: Callable[[], float] | None = None,
                 keymap: Mapping[str, str] | None = None) -> None:
        self.events = events
        self.kind = kind
        self.keymap = kind.keys if keymap is None else keymap  # raw input name -> the kind's answer
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
            if self.kind.needs_hand_pose:
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
