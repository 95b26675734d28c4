"""Keyboard responses through a small event interface (a window or the terminal supplies the events).

The keys are raw input; the response kind (psyop.protocol.kinds, carried by the session plan) maps each to
an answer (its ``keys``) and scores it. A kind whose answer is a hand position (reach) has its keys confirm
and the reach read from the hand pose. docs/protocols.md lists each kind's keys. :meth:`KeyboardResponses.poll_raw`
hands every key pressed, unmapped, to whoever interprets other input (a questionnaire item's scale points, the
end of a participant-paced interval: psyop.session.screens, psyop.session.loop).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Protocol

from psyop.session.rows import TrialRow
from psyop.session.responses.base import RawInput, Response, ResponseKindSpec, score

class KeyEvents(Protocol):
    """Source of key presses: ``poll`` returns (key name, time on the session clock) pairs."""

    def poll(self) -> list[tuple[str, float]]: ...


class MergedKeys:
    """Several key sources as one (the experimenter window and the terminal): every source's presses, in the
    order they were made."""

    def __init__(self, sources: list[KeyEvents]) -> None:
        self.sources = list(sources)

    def poll(self) -> list[tuple[str, float]]:
        keys = [key for source in self.sources for key in source.poll()]
        return sorted(keys, key=lambda key: key[1])


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

    def poll_raw(self) -> list[tuple[str, float, str | None]]:
        """Every key pressed since the last poll: (key name in lower case, time on the session clock, the kind's
        answer it maps to or None). What the key means is the caller's (the response phase uses :meth:`collect`)."""
        return [(key.lower(), t_s, self.keymap.get(key.lower())) for key, t_s in self.events.poll()]

    def raw_inputs(self, since_s: float, now_s: float) -> list[RawInput]:
        """Every mapped key pressed since ``since_s`` (the response phase's start), in order; earlier ones are
        counted in ``early_presses`` and dropped (an adjustment reads these, frame by frame)."""
        out: list[RawInput] = []
        for key, t_s in self.events.poll():
            name = self.keymap.get(key.lower())
            if name is None:
                continue
            if t_s < since_s:
                self.early_presses += 1
                continue
            out.append(RawInput(name, t_s))
        return out

    def timed_out(self) -> None:
        self._prompt_s = None

    def close(self) -> None:
        return None
