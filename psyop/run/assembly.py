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
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from psyop.session.rows import JsonObject
from psyop.optics.display import DisplayProfile
from psyop.errors import UserError
from psyop.run.backends import BackendContext, build
from psyop.run.backends import experimenter_window as make_experimenter_window
from psyop.session.clock import Clock
from psyop.session.events import EventSink
from psyop.session.frames import Display
from psyop.session.gaze.sample import GazeSource
from psyop.session.headset_calibration import HeadsetCalibration
from psyop.session.pose import PoseSource
from psyop.session.responses.base import ResponseSource

if TYPE_CHECKING:
    from psyop.devices.experimenter import ExperimenterWindow
    from psyop.devices.window import GlfwWindow

__all__ = ["Backends", "assemble", "display_used", "open_markers"]


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
    #: a window display's framebuffer as the window system made it (read while the window is open)
    framebuffer_px: tuple[int, int] | None = None
    #: ``--experimenter-window``: the display with the window's mirror (what the loop drives); None without it
    mirrored: Display | None = None
    #: the tracker's in-headset calibration (``pupil:...,calibrate-hmd``; psyop.session.headset_calibration); None: none
    headset_calibration: HeadsetCalibration | None = None

    @property
    def shown(self) -> Display:
        """The display the loop and the renderer drive: the mirrored one with an experimenter window, else
        ``display`` (which ``display_used`` and the tracking backends always see as it is)."""
        return self.mirrored if self.mirrored is not None else self.display

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


def assemble(specs: dict[str, str], context: BackendContext, markers: EventSink | None = None, *,
             experimenter_window: bool = False, window_optional: bool = False, terminal: bool = False) -> Backends:
    """Build the backends ``specs`` names (``{"display": ..., "tracker": ..., "pose": ..., "responses": ...}``),
    and with ``experimenter_window`` the experimenter's window right after the display
    (:func:`psyop.run.backends.experimenter_window`): it mirrors the display (``Backends.shown``), hears the
    trial events, counts the valid gaze samples and gives keyboard responses its keys (``window_optional``: the
    window was not asked for but is on by default: one that cannot open is a warning line, and the session runs
    without it). With ``terminal`` the terminal's keys are read (psyop.devices.responses.terminal) before the
    display is built, and its settings restored last.

    The closing order is the teardown the runner had by hand: responses, tracker, (raw gaze flush), pose,
    event sinks in the order they were added, the experimenter window, display."""
    keys = None
    with contextlib.ExitStack() as built:  # a backend that cannot be built closes those built before it
        if markers is not None:
            built.callback(markers.close)
        if terminal:
            from psyop.devices.responses.terminal import TerminalKeys

            keys = TerminalKeys(context.clock, context.controls)
            built.callback(keys.close)
            context = dataclasses.replace(context, terminal=keys)
        display = build("display", specs["display"], context)
        built.callback(display.close)
        context = dataclasses.replace(context, display=display)
        window = _experimenter_window(context, window_optional) if experimenter_window else None
        if window is not None:
            built.callback(window.close)
            context = dataclasses.replace(context, experimenter_window=window)
        gaze = build("tracker", specs["tracker"], context)
        built.callback(gaze.close)
        pose = build("pose", specs["pose"], context)
        built.callback(pose.close)
        responses = build("responses", specs["responses"], context)
        built.pop_all()
    events = ((markers,) if markers is not None else ()) + tuple(context.event_sinks)
    bundle = Backends(display, gaze, pose, responses, events + ((window,) if window is not None else ()),
                      framebuffer_px=_framebuffer_px(display))
    stack = bundle.stack
    stack.callback(keys.close if keys is not None else (lambda: None))
    stack.callback(display.close)
    if window is not None:
        from psyop.devices.experimenter import MirroredDisplay, WatchedGaze

        mirrored = MirroredDisplay(display, window)
        bundle.mirrored = mirrored
        bundle.gaze = WatchedGaze(gaze, window)
        stack.callback(window.close)
        stack.callback(mirrored.close)
    for sink in reversed(events):
        if sink is not gaze:  # a tracker that takes events is closed as the tracker
            stack.callback(sink.close)
    stack.callback(pose.close)
    stack.callback(lambda: bundle.after_tracker_closed())
    stack.callback(gaze.close)
    for calibration in context.headset_calibrations:  # closed before the tracker it calibrates
        stack.callback(calibration.close)
    bundle.headset_calibration = context.headset_calibrations[0] if context.headset_calibrations else None
    stack.callback(responses.close)
    return bundle


def _experimenter_window(context: BackendContext, optional: bool) -> ExperimenterWindow | None:
    """The experimenter window; when it is only on by default (``optional``), None and one warning line (stderr)
    where it cannot open."""
    try:
        return make_experimenter_window(context)
    except UserError as exc:
        if not optional:
            raise
        print(f"psyop run: warning: no experimenter window ({exc.message}); the session runs without the mirror "
              "(--no-mirror silences this)", file=sys.stderr, flush=True)
        return None


def _framebuffer_px(display: Display) -> tuple[int, int] | None:
    if display.name != "window":
        return None
    from psyop.devices.window import GlfwWindow

    return display.framebuffer_size_px() if isinstance(display, GlfwWindow) else None


def display_used(bundle: Backends, profile: DisplayProfile, eyes: Sequence[str], window_scale: float) -> JsonObject:
    """session.json's ``display_used`` block of this run (docs/data.md): the display as it really was.

    A headset: the runtime's swapchain size, field of view per eye and the rate measured from its predicted
    display times (:mod:`psyop.devices.xr.views_used`). A window: its framebuffer, each eye's image as
    presented (the profile's field of view at ``window_scale``) and the rate measured from the flip
    timestamps. Headless: the protocol's profile, nothing measured (no screen). Readable after the
    backends are closed."""
    display = bundle.display
    if display.name == "openxr":
        from psyop.devices.xr.display import OpenXRDisplay

        if isinstance(display, OpenXRDisplay):
            return {**display.views_used(), "profile": profile.name}
    if display.name == "window":
        from psyop.devices.window import GlfwWindow

        if isinstance(display, GlfwWindow):
            return _window_used(display, bundle.framebuffer_px, profile, eyes, window_scale)
    return {"display": display.name, "measured": False, "profile": profile.name,
            "source": "no screen: the protocol's display profile",
            "eyes": {eye: _profile_eye(profile, eye, profile.width_px, profile.height_px) for eye in eyes},
            "refresh_hz": float(profile.refresh_hz)}


def _profile_eye(profile: DisplayProfile, eye: str, width_px: int, height_px: int) -> JsonObject:
    tangents = profile.frustum_tangents(eye)
    return {"width_px": int(width_px), "height_px": int(height_px),
            **dict(zip(("tan_left", "tan_right", "tan_bottom", "tan_top"), tangents))}


def _window_used(window: GlfwWindow, framebuffer_px: tuple[int, int] | None, profile: DisplayProfile,
                 eyes: Sequence[str], window_scale: float) -> JsonObject:
    import numpy as np

    # each eye's image as SceneRenderer renders it for the window (texel = screen pixel when presented)
    width_px, height_px = max(16, round(profile.width_px * window_scale)), max(16, round(profile.height_px * window_scale))
    steps = np.diff(np.asarray(window.flips.times_s, dtype=np.float64))
    steps = steps[steps > 0]
    interval = float(np.median(steps)) if len(steps) else None
    return {"display": "window", "measured": True, "profile": profile.name,
            "source": "the window system's framebuffer; each eye's image as presented (the profile's field of "
                      f"view, rendered at --window-scale {window_scale:g}); rate from the flip timestamps (the last "
                      f"{window.flips.capacity} flips)",
            "framebuffer_px": list(framebuffer_px) if framebuffer_px is not None else None,
            "eyes": {eye: _profile_eye(profile, eye, width_px, height_px) for eye in eyes},
            "refresh_hz": 1.0 / interval if interval else None, "flip_interval_median_s": interval,
            "flip_intervals_measured": int(len(steps))}
