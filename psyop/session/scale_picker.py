"""A k-point scale (a rating, a confidence rating, an n_afc's n > 2 alternatives, a questionnaire item) answered with
the OpenXR controllers: a stick moves a highlighted point along the scale, a select button confirms it.

The source reports the stick's sideways deflection x in [-1, 1] (right positive) as the raw input
:data:`~psyop.protocol.kinds.confidence.SCALE_AXIS` whenever it changes, and a select button as any other mapped
input (psyop.devices.xr.tracking, through the kind's controller map). :class:`ScalePicker` reads them:

- the highlighted point starts at the scale's middle, :func:`start_point` ((k + 1) // 2: 4 of 7, 2 of 4);
- a flick is a deflection reaching :data:`FLICK_AT` (0.6) to the right (one point up) or the left (one point
  down), clipped to 1..k; the stick must then come back inside :data:`REARM_BELOW` (0.3) before the next flick
  counts, so a stick held over keeps the one step;
- any other input confirms the highlighted point at its time.

The path (every counted flick, also one a scale end stops, after the start) is JSON ``[[t_s, point], ...]``, t_s
from the scale's onset, as an adjustment's path is. :func:`run_picker` drives one picker frame by frame on the
loop's clock and display.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

from psyop.protocol.kinds.confidence import SCALE_AXIS
from psyop.session.clock import Clock
from psyop.session.frames import Display, FrameRequest
from psyop.session.responses.base import RawInput

#: a sideways deflection (of 1) at least this far is a flick: one point right (up) or left (down)
FLICK_AT = 0.6
#: after a flick, the stick must come back inside this deflection before the next flick counts
REARM_BELOW = 0.3


def start_point(points: int) -> int:
    """The point highlighted when a ``points``-point scale appears: its middle, the lower of two middles.

    Examples
    --------
    >>> start_point(7), start_point(4), start_point(2)
    (4, 2, 1)
    """
    return (int(points) + 1) // 2


@runtime_checkable
class MappedRawSource(Protocol):
    """A device source read raw through a kind's map (psyop.devices.responses.keyboard and its OpenXR subclass):
    ``keymap`` is raw input name -> the kind's name for it."""

    keymap: Mapping[str, str]

    def raw_inputs(self, since_s: float, now_s: float) -> list[RawInput]: ...


@runtime_checkable
class RemappableSource(Protocol):
    """A device source that reads its raw inputs through any map it is given (the OpenXR controllers,
    psyop.devices.xr.tracking): a questionnaire item reads them as a scale whatever the trial's kind maps."""

    def with_keymap(self, keymap: Mapping[str, str]) -> MappedRawSource: ...


def picks_on_scale(source: object) -> bool:
    """Whether ``source`` answers a scale with a stick: its map names :data:`SCALE_AXIS` (the OpenXR controllers for
    a rating or a confidence rating; a keyboard or box answers by digit instead)."""
    return isinstance(source, MappedRawSource) and SCALE_AXIS in source.keymap.values()


@dataclass
class ScalePicker:
    """The highlighted point of a ``points``-point scale shown at ``t0_s`` (session clock), moved by flicks and
    confirmed (see the module docstring).

    Examples
    --------
    >>> p = ScalePicker(5, t0_s=10.0)
    >>> for name, t_s, x in [("scale_axis", 10.5, 0.9), ("scale_axis", 10.6, 1.0), ("scale_axis", 10.7, 0.1),
    ...                      ("scale_axis", 10.8, 0.7), ("confirm", 11.0, 1.0)]:
    ...     p.apply(RawInput(name, t_s, x))
    >>> p.point, p.confirmed_s, p.path_json()
    (5, 11.0, '[[0.0,3],[0.5,4],[0.8,5]]')
    """

    points: int
    t0_s: float
    point: int = 0
    confirmed_s: float | None = None
    path: list[tuple[float, int]] = field(default_factory=list)
    armed: bool = True

    def __post_init__(self) -> None:
        self.point = start_point(self.points)
        self.path = [(0.0, self.point)]

    def apply(self, raw: RawInput) -> None:
        """One raw input: a stick deflection may flick, anything else confirms; none counts once confirmed."""
        if self.confirmed_s is not None:
            return
        if raw.name != SCALE_AXIS:
            self.confirmed_s = raw.t_s
            return
        x = float(raw.amount)
        if abs(x) < REARM_BELOW:
            self.armed = True
        elif self.armed and abs(x) >= FLICK_AT:
            self.armed = False
            self.point = min(max(self.point + (1 if x > 0 else -1), 1), int(self.points))
            self.path.append((raw.t_s - self.t0_s, self.point))

    def path_json(self) -> str:
        """The path as the trial log's ``*_path``: JSON ``[[t_s, point], ...]``."""
        return json.dumps([[round(float(t), 6), int(p)] for t, p in self.path], separators=(",", ":"))


@dataclass(frozen=True)
class PickerPacing:
    """How :func:`run_picker` waits: the loop's clock and display, the scale's timeout (None: it waits), whether a
    frame is drawn each period (a person watches) and the frame period."""

    clock: Clock
    display: Display
    timeout_s: float | None
    every_frame: bool
    frame_period_s: float


def run_picker(picker: ScalePicker, source: MappedRawSource, pacing: PickerPacing,
               draw: Callable[[FrameRequest, int], object]) -> ScalePicker:
    """Reads ``source`` into ``picker`` until it is confirmed or the timeout passes from ``picker.t0_s``, drawing
    each frame with the point highlighted at that time (``draw(request, point)``); returns the picker."""
    clock, display, timeout_s = pacing.clock, pacing.display, pacing.timeout_s
    start_s = picker.t0_s
    while True:
        now_s = clock.now_s()
        for raw in source.raw_inputs(start_s, now_s):
            picker.apply(raw)
        if picker.confirmed_s is not None or (timeout_s is not None and now_s - start_s >= timeout_s - 1e-9):
            return picker
        if pacing.every_frame:
            request = display.begin_frame(now_s)
            draw(request, picker.point)
            wake_s = max(clock.now_s(), request.display_time_s + request.period_s) if not clock.virtual \
                else clock.now_s() + pacing.frame_period_s
            if display.paced:
                continue
        else:
            wake_s = now_s + 0.01
        clock.sleep_until(wake_s if timeout_s is None else min(wake_s, start_s + timeout_s))
