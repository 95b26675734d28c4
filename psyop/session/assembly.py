"""Every backend of one session built into one bundle, and closed by it.

:func:`assemble` builds the LSL marker outlet (``--lsl-markers``), the display, the tracker, the pose
source and the response source, in that order (responses and headset trackers are built on the display).
The :class:`Backends` bundle owns them: one :class:`contextlib.ExitStack` closes them in reverse order
(the renderer, registered later by the lifecycle, first; the display last), whatever raises, so a
response source whose ``close`` raises still lets the display (an OpenXR session) close. A backend that
cannot be built closes those built before it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import sys
from collections.abc import Callable
from dataclasses import dataclass, field

from psyop.session.rows import JsonObject
from psyop.errors import UserError
from psyop.session.backends import BackendContext, build
from psyop.session.clock import Clock
from psyop.session.events import EventSink
from psyop.session.frames import Display
from psyop.session.gaze.sample import GazeSource
from psyop.session.pose import PoseSource
from psyop.session.responses.base import ResponseSource

__all__ = ["Backends", "assemble", "open_markers"]


@dataclass
class Backends:
    """The built backends of one session and the stack that closes them.

    ``events``: every trial-event sink (the marker outlet, then those the backends added, e.g. Pupil
    annotations); ``after_tracker_closed``: run once the tracker is closed, before the pose source (the
    lifecycle flushes the raw gaze samples no trial recorded there)."""

    display: Display
    gaze: GazeSource
    pose: PoseSource
    responses: ResponseSource
    events: tuple[EventSink, ...]
    stack: contextlib.ExitStack = field(default_factory=contextlib.ExitStack)
    after_tracker_closed: Callable[[], None] = lambda: None

    def __enter__(self) -> Backends:
        return self

    def __exit__(self, *exc: object) -> bool | None:
        return self.stack.__exit__(*exc)  # type: ignore[arg-type]  # the exception triple, passed on as given


def open_markers(metadata: JsonObject, clock: Clock, wait_s: float) -> EventSink:
    """The LSL marker outlet of ``--lsl-markers``; waits ``wait_s`` for a recorder, records whether one came."""
    if clock.virtual:
        raise UserError("--lsl-markers stamps events on the LSL clock in real time; on --clock virtual they would "
                        "carry times that never happened: use --clock real", "--clock")
    from psyop.devices.lsl_markers import LslMarkerOutlet

    markers = LslMarkerOutlet(dict(metadata), clock.now_s)
    recorded = markers.wait_for_recorder(wait_s)
    print("psyop run: LSL marker stream 'psyop_markers': "
          + ("a recorder is connected" if recorded else f"no recorder connected within {wait_s:g} s; "
             "markers sent before one connects are recorded by nobody"), file=sys.stderr)
    metadata["lsl_markers_recorder_at_start"] = recorded
    return markers


def assemble(specs: dict[str, str], context: BackendContext, markers: EventSink | None = None) -> Backends:
    """Build the backends ``specs`` names (``{"display": ..., "tracker": ..., "pose": ..., "responses": ...}``).

    The closing order is the teardown the runner had by hand: responses, tracker, (raw gaze flush), pose,
    event sinks in the order they were added, display."""
    with contextlib.ExitStack() as built:  # a backend that cannot be built closes those built before it
        if markers is not None:
            built.callback(markers.close)
        display = build("display", specs["display"], context)
        built.callback(display.close)
        context = dataclasses.replace(context, display=display)
        gaze = build("tracker", specs["tracker"], context)
        built.callback(gaze.close)
        pose = build("pose", specs["pose"], context)
        built.callback(pose.close)
        responses = build("responses", specs["responses"], context)
        built.pop_all()
    events = ((markers,) if markers is not None else ()) + tuple(context.event_sinks)
    bundle = Backends(display, gaze, pose, responses, events)
    stack = bundle.stack
    stack.callback(display.close)
    for sink in reversed(events):
        if sink is not gaze:  # a tracker that takes events is closed as the tracker
            stack.callback(sink.close)
    stack.callback(pose.close)
    stack.callback(lambda: bundle.after_tracker_closed())
    stack.callback(gaze.close)
    stack.callback(responses.close)
    return bundle
