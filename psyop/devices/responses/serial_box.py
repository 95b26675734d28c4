"""A serial response box: each button press arrives as one line ``B<button>``.

The button is raw input; the response kind (psyop.protocol.kinds) maps it to an answer (its ``buttons``;
docs/protocols.md lists them) and scores it. Digit buttons ``B0`` .. ``B9`` are kept too, whether they answer
the kind or not (:meth:`SerialResponseBox.poll_raw` hands them to a questionnaire item: psyop.session.screens;
one that answers nothing of the kind still counts in ``garbage``); garbage bytes and other lines are counted and
skipped.
"""

from __future__ import annotations

import queue
from collections.abc import Callable, Mapping

from psyop.session.rows import TrialRow
from psyop.session.responses.base import RawInput, Response, ResponseKindSpec, score
from psyop.devices.serial_lines import SerialLineReader

class SerialResponseBox:
    needs_images = True

    def __init__(self, url: str, kind: ResponseKindSpec, *, clock: Callable[[], float], baudrate: int = 115200,
                 buttons: Mapping[str, str] | None = None) -> None:
        self.buttons = kind.buttons if buttons is None else buttons  # button -> the kind's answer
        if not self.buttons:
            raise ValueError(f"a response box cannot give {kind.name} responses")
        self.kind = kind
        self._presses: queue.Queue[tuple[str, float]] = queue.Queue()
        self._reader = SerialLineReader(url, self._on_line, clock, baudrate=baudrate)
        self._prompt_s: float | None = None
        self._reader.start()

    def _on_line(self, text: str, arrival_s: float) -> bool:
        text = text.strip()
        if len(text) != 2 or text[0] != "B" or not (text[1] in self.buttons or text[1].isdigit()):
            return False
        self._presses.put((text[1], arrival_s))
        return text[1] in self.buttons  # a digit that answers nothing of the kind: kept raw, counted as before

    def collect(self, row: TrialRow, now_s: float) -> Response | None:
        if self._prompt_s is None:
            self._prompt_s = now_s
            while not self._presses.empty():  # presses before the prompt do not count
                self._presses.get_nowait()
            return None
        while True:
            try:
                button, t_s = self._presses.get_nowait()
            except queue.Empty:
                if self._reader.error:
                    raise ConnectionError(self._reader.error) from None
                return None
            if button in self.buttons:  # a digit button that answers nothing of this kind is skipped
                break
        r = score(self.kind, row, self.buttons[button])
        rt = t_s - self._prompt_s
        self._prompt_s = None
        return Response(r.response, r.correct, r.reach_m, r.chosen_mode, rt)

    def poll_raw(self) -> list[tuple[str, float, str | None]]:
        """Every button pressed since the last poll: (button, arrival time on the session clock, the kind's
        answer it maps to or None); the caller interprets them (the response phase uses :meth:`collect`)."""
        presses: list[tuple[str, float, str | None]] = []
        while True:
            try:
                button, t_s = self._presses.get_nowait()
            except queue.Empty:
                if self._reader.error:
                    raise ConnectionError(self._reader.error) from None
                return presses
            presses.append((button, t_s, self.buttons.get(button)))

    def raw_inputs(self, since_s: float, now_s: float) -> list[RawInput]:
        """Every button pressed since ``since_s`` (the response phase's start), in order; earlier presses are
        dropped (an adjustment reads these, frame by frame)."""
        out: list[RawInput] = []
        while True:
            try:
                button, t_s = self._presses.get_nowait()
            except queue.Empty:
                break
            name = self.buttons.get(button)
            if name is not None and t_s >= since_s:
                out.append(RawInput(name, t_s))
        if not out and self._reader.error:
            raise ConnectionError(self._reader.error)
        return out

    def stats(self) -> dict[str, int]:
        with self._reader.lock:
            return {"lines": self._reader.lines, "garbage": self._reader.garbage}

    def timed_out(self) -> None:
        self._prompt_s = None

    def close(self) -> None:
        self._reader.close()
