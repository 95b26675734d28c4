"""The confidence rating a protocol asks after a trial's choice (``response: confidence:``,
psyop.protocol.kinds.confidence): the response phase's second step.

Once the choice is collected, :class:`ConfidenceAsker` shows the scale's question and points on a head-fixed text
panel (a :class:`~psyop.session.screens.ScreenPhase`, drawn as a session screen is) and asks the same response
source for a point:

- a simulated observer answers at once from its stated confidence model (``confidence(row, points)``);
- a keyboard or a serial response box is read raw (``poll_raw``): a digit key 1..k (top row or keypad) or box
  button 1..k is the answer; any other input, and any pressed before the scale appeared (the choice's own key),
  is ignored;
- the OpenXR controllers (a source whose map names the stick's sideways axis) pick the point with a stick and
  confirm it with a select button (psyop.session.scale_picker): the highlighted point is marked on the panel each
  frame, and its path goes to ``confidence_path``;
- a source that offers neither (``--responses none``) never answers: the scale runs to its timeout.

The scale has the response's ``timeout_s`` (none: it waits); a scale that times out is logged with
``confidence_outcome`` ``timeout``. A choice that timed out is not followed by a scale (``not_asked``). The
answer goes to the trial log as the columns of :func:`confidence_extras`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Protocol, runtime_checkable

from psyop.datacontract import TIMEOUT_RESPONSE
from psyop.protocol.kinds.confidence import (CONFIDENCE, CONFIDENCE_OUTCOME, CONFIDENCE_PATH, CONFIDENCE_TIME_S,
                                             ConfidenceScale, confidence_point, confidence_text)
from psyop.session.clock import Clock
from psyop.session.frames import Display, FrameRequest
from psyop.session.responses.base import Response
from psyop.session.rows import TrialRow
from psyop.session.scale_picker import (MappedRawSource, PickerPacing, ScalePicker, picks_on_scale, run_picker,
                                       start_point)
from psyop.session.screens import ScreenPhase


@runtime_checkable
class RatesConfidence(Protocol):
    """A simulated observer's side of the seam: its confidence in its answer to ``row`` (None: it has no model)."""

    def confidence(self, row: TrialRow, points: int) -> int | None: ...


@runtime_checkable
class RawPresses(Protocol):
    """A person's source read raw (the keyboard, the serial box): every input since the last poll as (name, time
    on the session clock, the kind's answer or None)."""

    def poll_raw(self) -> list[tuple[str, float, str | None]]: ...


def confidence_extras(point: int | None, time_s: float, outcome: str) -> tuple[tuple[str, float | str], ...]:
    """The trial-log values of a confidence rating: the point (NaN, logged null: none), its time from the scale's
    onset (s) and the outcome (answered, timeout, not_asked)."""
    return ((CONFIDENCE, math.nan if point is None else float(point)), (CONFIDENCE_TIME_S, time_s),
            (CONFIDENCE_OUTCOME, outcome))


class ConfidenceAsker:
    """Asks one trial's confidence on ``scale`` from ``source`` (see the module docstring): ``draw`` renders one
    frame of :attr:`phase` for a display request (the loop's frame path) when a person watches."""

    def __init__(self, scale: ConfidenceScale, source: object, clock: Clock, display: Display, *,
                 timeout_s: float | None, every_frame: bool, frame_period_s: float) -> None:
        self.scale, self.points, self.source = scale, int(scale.points), source
        self.clock, self.display = clock, display
        self.timeout_s, self.every_frame, self.frame_period_s = timeout_s, every_frame, frame_period_s
        marked = start_point(self.points) if picks_on_scale(source) else None  # the controllers move a marker
        self.phase = ScreenPhase("confidence", 0.0, "text", "cross", text=confidence_text(scale, marked))

    def ask(self, row: TrialRow, response: Response, draw: Callable[[FrameRequest], object]) -> Response:
        """``response`` with the confidence's columns added (not asked after a timed-out choice)."""
        if response.response == TIMEOUT_RESPONSE:
            return self._with(response, None, math.nan, "not_asked")
        start_s = self.clock.now_s()
        if isinstance(self.source, RatesConfidence):
            rated = self.source.confidence(row, self.points)
            return self._with(response, rated, 0.0, "answered") if rated is not None else \
                self._with(response, None, math.nan, "not_asked")
        if picks_on_scale(self.source):
            return self._picked(response, start_s, draw)
        while True:
            now_s = self.clock.now_s()
            point = self._pressed(start_s)
            if point is not None:
                return self._with(response, point[0], point[1] - start_s, "answered")
            if self.timeout_s is not None and now_s - start_s >= self.timeout_s - 1e-9:
                return self._with(response, None, math.nan, "timeout")
            if self.every_frame:
                request = self.display.begin_frame(now_s)
                draw(request)
                wake_s = max(self.clock.now_s(), request.display_time_s + request.period_s) if not \
                    self.clock.virtual else self.clock.now_s() + self.frame_period_s
                if self.display.paced:
                    continue
            else:
                wake_s = now_s + 0.01
            self.clock.sleep_until(wake_s if self.timeout_s is None else min(wake_s, start_s + self.timeout_s))

    def _picked(self, response: Response, start_s: float, draw: Callable[[FrameRequest], object]) -> Response:
        """The point the controllers' stick highlights and a select button confirms, drawn marked each frame."""
        assert isinstance(self.source, MappedRawSource)

        def draw_marked(request: FrameRequest, point: int) -> object:
            self.phase = ScreenPhase("confidence", 0.0, "text", "cross", text=confidence_text(self.scale, point))
            return draw(request)

        picker = run_picker(ScalePicker(self.points, start_s), self.source,
                            PickerPacing(self.clock, self.display, self.timeout_s, self.every_frame,
                                         self.frame_period_s), draw_marked)
        path = ((CONFIDENCE_PATH, picker.path_json()),)
        if picker.confirmed_s is None:
            with_scale = self._with(response, None, math.nan, "timeout")
        else:
            with_scale = self._with(response, picker.point, picker.confirmed_s - start_s, "answered")
        return dataclasses.replace(with_scale, extras=with_scale.extras + path)

    def _pressed(self, start_s: float) -> tuple[int, float] | None:
        """The first scale point pressed since ``start_s`` (point, time), or None."""
        if not isinstance(self.source, RawPresses):
            return None
        for name, t_s, _ in self.source.poll_raw():
            point = confidence_point(name, self.points)
            if point is not None and t_s >= start_s:
                return point, t_s
        return None

    @staticmethod
    def _with(response: Response, point: int | None, time_s: float, outcome: str) -> Response:
        return dataclasses.replace(response, extras=response.extras + confidence_extras(point, time_s, outcome))
