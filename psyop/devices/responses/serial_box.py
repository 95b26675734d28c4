"""A serial response box: each button press arrives as one line ``B<button>``.

The button is raw input; the response kind (psyop.protocol.kinds) maps it to an answer (its ``buttons``;
docs/protocols.md lists them) and scores it. Garbage bytes and unknown lines are counted and skipped.
"""

from __future__ import annotations

import queue
from collections.abc import Callable, Mapping

from psyop.session.rows import TrialRow
from psyop.session.responses.base import Response, ResponseKindSpec, score
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
        if len(text) != 2 or text[0] != "B" or text[1] not in self.buttons:
            return False
        self._presses.put((text[1], arrival_s))
        return True

    def collect(self, row: TrialRow, now_s: float) -> Response | None:
        if self._prompt_s is None:
            self._prompt_s = now_s
            while not self._presses.empty():  # presses before the prompt do not count
                self._presses.get_nowait()
            return None
        try:
            button, t_s = self._presses.get_nowait()
        except queue.Empty:
            if self._reader.error:
                raise ConnectionError(self._reader.error) from None
            return None
        r = score(self.kind, row, self.buttons[button])
        rt = t_s - self._prompt_s
        self._prompt_s = None
        return Response(r.response, r.correct, r.reach_m, r.chosen_mode, rt)

    def stats(self) -> dict[str, int]:
        with self._reader.lock:
            return {"lines": self._reader.lines, "garbage": self._reader.garbage}

    def timed_out(self) -> None:
        self._prompt_s = None

    def close(self) -> None:
        self._reader.close()
