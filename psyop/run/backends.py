"""The backend registry: every gaze tracker, pose source, response source and display a session can use.

One frozen :class:`Backend` per backend says what ``psyop run`` needs to know about it: its
category and name, the option string it parses (``usage``, e.g. ``pupil:HOST:PORT``), a one-line
summary (the ``--help`` text is generated from these), whether it runs in real time (refused on
``--clock virtual``), the pip extra that brings its optional dependency and the modules that
extra provides (checked before construction), and a factory ``make(arg, ctx)``. Adding a backend
is one entry in :data:`BACKENDS` (and its module).

The runner builds the display first (:func:`build` with ``ctx.display`` None), then gaze, pose
and responses with ``ctx.display`` set: keyboard responses read the window's keys, headset
trackers use the headset session.

Examples
--------
>>> [b.name for b in backends("display")]
['headless', 'window', 'openxr']
>>> lookup("tracker", "pupil:127.0.0.1:50020")[1]
'127.0.0.1:50020'
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Generic, Literal, TypeVar, overload

from psyop.errors import UserError

if TYPE_CHECKING:
    import pandas as pd

    from psyop.devices.experimenter import ExperimenterWindow
    from psyop.devices.responses.keyboard import KeyEvents
    from psyop.session.clock import Clock
    from psyop.session.controls import SessionControls
    from psyop.session.events import EventSink
    from psyop.session.frames import Display
    from psyop.session.gaze.sample import GazeSource
    from psyop.session.gaze.simulated import SimulatedTrackerConfig
    from psyop.session.loop import BetweenTrials
    from psyop.session.headset_calibration import HeadsetCalibration
    from psyop.session.plan import SessionPlan
    from psyop.session.pose import PoseSource
    from psyop.session.responses.base import ResponseSource

Category = Literal["tracker", "pose", "responses", "display"]
CATEGORIES: tuple[Category, ...] = ("tracker", "pose", "responses", "display")
#: the command-line option of each category
OPTION: dict[Category, str] = {"tracker": "--tracker", "pose": "--pose", "responses": "--responses",
                               "display": "--display"}
T = TypeVar("T")


@dataclass(frozen=True)
class BackendContext:
    """What factories are given: the session's clock, seed, plan, participant, schedule and
    protocol hash (pose replay checks them), the simulated tracker's fault configuration, the
    window scale (``--window-scale``), the session number, ``display``: the display already built
    (None while the display itself is being built), and ``event_sinks``: where a backend that wants
    the session's trial events (:mod:`psyop.session.events`, e.g. Pupil annotations) adds itself;
    the runner hands them to the loop."""

    clock: Clock
    seed: int
    plan: SessionPlan
    participant: str
    protocol_sha256: str
    schedule: pd.DataFrame
    tracker_faults: SimulatedTrackerConfig
    window_scale: float = 0.25
    display: Display | None = None
    session: int = 1
    event_sinks: list[EventSink] = field(default_factory=list)
    xr_request_exit_at_frame: int | None = None  # testing aid: the OpenXR runtime is asked to stop at frame N
    #: the experimenter window (``--experimenter-window``; None without it): keyboard responses read its keys
    #: when the display is no window of its own
    experimenter_window: KeyEvents | None = None
    #: the terminal's keys (psyop.devices.responses.terminal; None: standard input is no foreground terminal, or
    #: the clock is virtual): keyboard responses read them too
    terminal: KeyEvents | None = None
    #: where every key source hands Escape, ``p`` and ``c`` (psyop.session.controls; None: no controls)
    controls: SessionControls | None = None
    #: the experimenter window's mirror: which eye (left, right or both) and each eye's width (pixels)
    mirror_eye: str = "left"
    mirror_width_px: int = 320
    #: where a backend adds what ``c`` (recalibrate now) runs at the next trial boundary, before the protocol's gaze
    #: validation, e.g. a tracker's own calibration: fn(loop, trial about to run) (psyop.session.loop.BetweenTrials;
    #: the runner hands them to the loop's ``on_recalibrate``)
    on_recalibrate: list[BetweenTrials] = field(default_factory=list)
    #: where a tracker calibrated in the headset (``pupil:...,calibrate-hmd``) adds its calibration
    #: (psyop.session.headset_calibration); the runner runs it before the first trial
    headset_calibrations: list[HeadsetCalibration] = field(default_factory=list)


@dataclass(frozen=True)
class Backend(Generic[T]):
    """One registered backend (see the module docstring).

    ``usage``: the option string, ``NAME`` or ``NAME:ARG`` (what ``--help`` shows); ``takes_arg``
    says whether ``ARG`` is required (True), refused (False) or optional (None). ``modules``: what
    ``extra`` installs, imported before ``make`` runs (a missing one is a UserError naming the
    ``pip install`` that fixes it)."""

    category: Category
    name: str
    usage: str
    summary: str
    real_time: bool
    make: Callable[[str, BackendContext], T]
    extra: str | None = None
    modules: tuple[str, ...] = ()
    takes_arg: bool | None = False

    def check_installed(self) -> None:
        """Import ``modules``; a missing one is a one-line UserError (exit code 2) naming the extra."""
        for module in self.modules:
            try:
                importlib.import_module(module)
            except (ImportError, OSError, RuntimeError) as exc:
                fix = f"pip install 'psyop[{self.extra}]'" if self.extra else f"install {module}"
                raise UserError(f"{OPTION[self.category]} {self.name} needs {module} ({exc.__class__.__name__}: "
                                f"{str(exc)[:120]}): {fix}", OPTION[self.category]) from exc

    def check_arg(self, spec: str, arg: str) -> None:
        if self.takes_arg is True and not arg:
            raise UserError(f"expected {self.usage}, got {spec!r}", OPTION[self.category])
        if self.takes_arg is False and arg:
            raise UserError(f"{self.name} takes no ':' argument; expected {self.usage}, got {spec!r}",
                            OPTION[self.category])


if TYPE_CHECKING:
    #: one registered backend: each kind's factory returns that kind's seam (see :func:`build`)
    AnyBackend = Backend[GazeSource] | Backend[PoseSource] | Backend[ResponseSource] | Backend[Display]


# -- factories (each imports its backend's module only when used) ----------------------------------

def _sim_tracker(arg: str, ctx: BackendContext) -> GazeSource:
    from psyop.session.gaze.simulated import SimulatedTracker, seed_for, tracker_config

    eye = ctx.plan.observer.eye if ctx.plan.observer is not None else None  # the protocol's observer: eye:
    return SimulatedTracker(seed_for(ctx.seed, "tracker"), tracker_config(eye, ctx.participant, ctx.tracker_faults))


def _replay_tracker(arg: str, ctx: BackendContext) -> GazeSource:
    from psyop.session.gaze.replay import ReplayTracker

    return ReplayTracker.from_path(Path(arg))


PUPIL_FLAGS = ("calibrate", "calibrate-hmd", "record", "annotate")


def _pupil_tracker(arg: str, ctx: BackendContext) -> GazeSource:
    from psyop.devices.gaze.pupil import PupilClient

    address, *flags = arg.split(",")
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise UserError(f"expected pupil:HOST:PORT[,calibrate|,calibrate-hmd][,record][,annotate], got 'pupil:{arg}'",
                        "--tracker")
    unknown = [f for f in flags if f not in PUPIL_FLAGS]
    if unknown:
        raise UserError(f"unknown pupil option(s) {unknown}; use {', '.join(PUPIL_FLAGS)}", "--tracker")
    if "calibrate" in flags and "calibrate-hmd" in flags:
        raise UserError("pupil options calibrate (Capture's own markers, on a monitor) and calibrate-hmd (psyop's "
                        "targets in the headset) are two calibrations: keep one", "--tracker")
    record = f"{ctx.plan.study}_sub-{ctx.participant}_ses-{ctx.session}" if "record" in flags else None
    client = PupilClient(host, int(port), clock=ctx.clock.now_s, calibrate="calibrate" in flags,
                         record_name=record, annotate="annotate" in flags)
    if client.annotate:
        ctx.event_sinks.append(client)
    if "calibrate-hmd" in flags:
        from psyop.devices.gaze.pupil_hmd_calibration import PupilHmdCalibration

        ctx.headset_calibrations.append(PupilHmdCalibration(client))
    return client


def _serial_tracker(arg: str, ctx: BackendContext) -> GazeSource:
    from psyop.devices.gaze.serial_source import SerialGazeSource

    return SerialGazeSource(arg, clock=ctx.clock.now_s)


def _lsl_tracker(arg: str, ctx: BackendContext) -> GazeSource:
    from psyop.devices.gaze.lsl import LslGazeSource, parse_spec

    name, channel_map = parse_spec(arg)
    return LslGazeSource(name, clock=ctx.clock.now_s, channel_map=channel_map)


def _sim_pose(arg: str, ctx: BackendContext) -> PoseSource:
    from psyop.session.gaze.simulated import seed_for
    from psyop.session.pose import SimulatedPose

    return SimulatedPose(seed_for(ctx.seed, "pose"))


def _replay_pose(by_condition: bool) -> Callable[[str, BackendContext], PoseSource]:
    def make(arg: str, ctx: BackendContext) -> PoseSource:
        from psyop.session.pose_replay import ReplayPose, ReplaySchedule

        schedule = ctx.schedule
        conditions = tuple(schedule["condition"].astype(str)) if "condition" in schedule else ()
        target = ReplaySchedule(ctx.protocol_sha256, ctx.seed, conditions)
        return ReplayPose.from_path(Path(arg), target, by_condition=by_condition)

    return make


def _sim_responses(arg: str, ctx: BackendContext) -> ResponseSource:
    from psyop.session.responses.simulated import make_observer

    params = ctx.plan.observer_params()
    if params is None:
        raise UserError("--responses sim needs an observer: section in the protocol", "protocol")
    if params.get("kind") == "image":  # answers from the frames it renders: it takes the session plan
        from psyop.session.responses.image_observer import image_observer_source

        return image_observer_source(params, seed=ctx.seed, participant=ctx.participant, plan=ctx.plan)
    return make_observer(params, seed=ctx.seed, participant=ctx.participant)


def _no_responses(arg: str, ctx: BackendContext) -> ResponseSource:
    from psyop.session.responses.none import NoResponses

    if ctx.plan.response.timeout_s is None:
        raise UserError("--responses none: nobody answers, and the protocol's response phase has no timeout_s, "
                        "so the session would wait forever; add timeout_s to it or use --responses sim",
                        "--responses")
    return NoResponses()


def _serial_responses(arg: str, ctx: BackendContext) -> ResponseSource:
    from psyop.devices.responses.serial_box import SerialResponseBox

    try:
        return SerialResponseBox(arg, ctx.plan.kind, clock=ctx.clock.now_s, buttons=ctx.plan.response.inputs.buttons)
    except (ValueError, ConnectionError) as exc:
        raise UserError(str(exc), "--responses") from exc


def _keyboard_responses(arg: str, ctx: BackendContext) -> ResponseSource:
    from psyop.devices.responses.keyboard import KeyboardResponses, MergedKeys
    from psyop.devices.window import GlfwWindow

    window: KeyEvents | None = ctx.display if isinstance(ctx.display, GlfwWindow) else ctx.experimenter_window
    sources = [s for s in (window, ctx.terminal) if s is not None]
    if not sources:
        raise UserError(KEYBOARD_NEEDS_KEYS, "--responses")
    keys = sources[0] if len(sources) == 1 else MergedKeys(sources)
    return KeyboardResponses(keys, ctx.plan.kind, keymap=ctx.plan.response.inputs.keys)


KEYBOARD_NEEDS_KEYS = (
    "--responses keyboard reads the keys of a window (the session window of --display window, or the experimenter "
    "window of --experimenter-window) or of the terminal psyop run was started from, and none is here: standard "
    "input is not a terminal in the foreground; run it from a terminal (`psyop run ... --display headless "
    "--responses keyboard --clock real`), or add --display window or --experimenter-window")


def _openxr_tracker(arg: str, ctx: BackendContext) -> GazeSource:
    from psyop.devices.xr.tracking import OpenXRGaze

    return OpenXRGaze.on_display(ctx.display)


def _openxr_pose(arg: str, ctx: BackendContext) -> PoseSource:
    from psyop.devices.xr.tracking import OpenXRPose

    return OpenXRPose.on_display(ctx.display, arg)


def _openxr_responses(arg: str, ctx: BackendContext) -> ResponseSource:
    from psyop.devices.xr.tracking import THUMBSTICK_X, OpenXRResponses
    from psyop.protocol.kinds.confidence import SCALE_CONTROLLER

    controller = dict(ctx.plan.response.inputs.controller)
    if ctx.plan.protocol.response.confidence is not None and controller:  # the stick picks the confidence point
        controller[THUMBSTICK_X] = SCALE_CONTROLLER[THUMBSTICK_X]
    return OpenXRResponses.on_display(ctx.display, ctx.plan.kind, controller)


def _headless_display(arg: str, ctx: BackendContext) -> Display:
    from psyop.session.frames import HeadlessDisplay

    return HeadlessDisplay(ctx.clock, float(ctx.plan.display.refresh_hz))


def _openxr_display(arg: str, ctx: BackendContext) -> Display:
    from psyop.devices.xr.display import open_openxr_display

    from psyop.devices.xr.binding import GRAPHICS_APIS

    if arg not in ("", "auto", *GRAPHICS_APIS):
        raise UserError(f"--display openxr:{arg}: expected openxr, openxr:egl or openxr:xlib (the OpenGL binding)",
                        "--display")
    from psyop.session.clock import RealClock

    if not isinstance(ctx.clock, RealClock):  # resume.check_options refuses this first (openxr is real time)
        raise UserError("--display openxr runs on the runtime's clock: use --clock real", "--clock")
    return open_openxr_display(ctx.plan, ctx.clock, ctx.xr_request_exit_at_frame, graphics=arg or "auto")


def _window_display(arg: str, ctx: BackendContext) -> Display:
    from psyop.devices.window import GlfwWindow

    return GlfwWindow(ctx.plan.display, ctx.clock, scale=ctx.window_scale, n_eyes=len(ctx.plan.rig.eyes),
                      controls=ctx.controls)


#: what ``--experimenter-window`` does (its ``--help``)
EXPERIMENTER_WINDOW_HELP = (
    "open a small window on the experimenter's screen: a mirror of the participant's view (--mirror-eye, "
    "--mirror-width-px; downscaled, about 15 updates a second) and a status line (trial k of N, condition, phase, "
    "last answer, dropped frames, gaze valid share); --responses keyboard then reads its keys, and Escape, p (pause) "
    "and c (recalibrate) work in it. With --display openxr or headless; on by default with --display openxr where "
    "a desktop display exists ($DISPLAY or $WAYLAND_DISPLAY; --no-mirror: off) (pip install 'psyop[window]')")

#: the eyes ``--mirror-eye`` may name, and the eyes each mirrors (side by side)
MIRROR_EYES: dict[str, tuple[str, ...]] = {"left": ("left",), "right": ("right",), "both": ("left", "right")}


def experimenter_window(ctx: BackendContext) -> ExperimenterWindow:
    """The experimenter window of ``--experimenter-window`` for the display ``ctx.display`` (built first): its
    context made through the display's API (GLX for ``openxr:xlib``, else EGL), its mirror the shape of the
    display's eye image (the runtime's swapchain, else the protocol's display profile)."""
    from psyop.devices.window import GlfwWindow

    if ctx.display is None or isinstance(ctx.display, GlfwWindow):
        raise UserError("--experimenter-window is for a display the experimenter cannot see (--display openxr or "
                        "headless); the session window already shows the session", "--experimenter-window")
    lookup("display", "window")[0].check_installed()  # glfw, as the window display needs it
    from psyop.devices.experimenter import MIRROR_WIDTH_PX, ExperimenterWindow

    width_px, height_px = ctx.plan.display.width_px, ctx.plan.display.height_px
    egl = True
    if ctx.display.name == "openxr":
        from psyop.devices.xr.display import OpenXRDisplay

        if isinstance(ctx.display, OpenXRDisplay):
            width_px, height_px = ctx.display.runtime.facts.recommended_sizes_px[0]
            egl = ctx.display.runtime.facts.graphics != "xlib"
    if ctx.mirror_eye not in MIRROR_EYES:
        raise UserError(f"--mirror-eye {ctx.mirror_eye}: expected one of {', '.join(MIRROR_EYES)}", "--mirror-eye")
    if not 16 <= ctx.mirror_width_px <= 4096:
        raise UserError(f"--mirror-width-px {ctx.mirror_width_px}: expected 16 to 4096 pixels per eye "
                        f"(default {MIRROR_WIDTH_PX})", "--mirror-width-px")
    width = int(ctx.mirror_width_px)
    mirror_px = (width, max(16, round(width * height_px / width_px)))
    return ExperimenterWindow(ctx.clock, len(ctx.schedule), mirror_px, egl=egl, restore=ctx.display.gl_context,
                              controls=ctx.controls, eyes=MIRROR_EYES[ctx.mirror_eye])


#: Every backend, in the order ``--help`` lists them.
BACKENDS: tuple[AnyBackend, ...] = (
    Backend("tracker", "sim", "sim", "simulated binocular tracker (120 Hz, blinks, drift; from the seed)",
            False, _sim_tracker),
    Backend("tracker", "replay", "replay:FILE", "the gaze of a logged session (frames.parquet or its session "
            "directory)", False, _replay_tracker, takes_arg=True),
    Backend("tracker", "pupil", "pupil:HOST:PORT[,calibrate|,calibrate-hmd][,record][,annotate]", "Pupil "
            "Capture/Service over the Pupil Core Network API (Pupil Remote's port, usually 50020); calibrate: run "
            "Capture's calibration first and stop if it fails; calibrate-hmd: calibrate in the headset before the "
            "first trial (psyop shows the targets, Capture's HMD 3D calibration fits them) and stop if it fails; record: a Capture recording named after the session; annotate: one annotation "
            "per recorded trial", True, _pupil_tracker, takes_arg=True),
    Backend("tracker", "serial", "serial:DEVICE", "a serial device sending 'G x_m y_m z_m confidence' lines",
            True, _serial_tracker, takes_arg=True),
    Backend("tracker", "lsl", "lsl:NAME[@MAP]", "a Lab Streaming Layer gaze stream by name (else type); channels "
            "by label: MAP is pupil_capture (Pupil Capture's relay), neon or a JSON map file, detected when left out",
            True, _lsl_tracker, extra="lsl", modules=("pylsl",), takes_arg=True),
    Backend("tracker", "openxr", "openxr", "eye gaze through the OpenXR runtime (XR_EXT_eye_gaze_interaction; "
            "needs --display openxr)", True, _openxr_tracker),
    Backend("pose", "sim", "sim", "simulated head sway and hand tracker (from the seed)", False, _sim_pose),
    Backend("pose", "replay", "replay:SESSION_DIR", "a logged session with the same schedule (protocol, seed, "
            "conditions)", False, _replay_pose(False), takes_arg=True),
    Backend("pose", "replay-by-condition", "replay-by-condition:SESSION_DIR", "each trial replays a logged "
            "trial of the same condition", False, _replay_pose(True), takes_arg=True),
    Backend("pose", "openxr", "openxr[:HAND]", "head pose from the OpenXR runtime (needs --display openxr); HAND "
            "adds the hand: left or right (grip pose), left:aim or right:aim (pointing pose), or vive_tracker:ROLE",
            True, _openxr_pose, takes_arg=None),
    Backend("responses", "sim", "sim", "the protocol's simulated observer", False, _sim_responses),
    Backend("responses", "keyboard", "keyboard", "keys of the session window (--display window), of the "
            "experimenter window (--experimenter-window) and of the terminal psyop run was started from (any display)",
            True,
            _keyboard_responses),
    Backend("responses", "serial", "serial:DEVICE", "a response box sending 'B<button>' lines", True,
            _serial_responses, takes_arg=True),
    Backend("responses", "none", "none", "nobody answers: every response phase runs to the protocol's timeout_s and "
            "is logged as a timeout (a dry run of the timing; needs timeout_s)", False, _no_responses),
    Backend("responses", "openxr", "openxr", "controller buttons through the OpenXR runtime (needs --display openxr)",
            True, _openxr_responses),
    Backend("display", "headless", "headless", "no screen: frames are rendered off-screen (or only their "
            "cameras)", False, _headless_display),
    Backend("display", "window", "window", "a desktop window showing each eye (pip install 'psyop[window]')",
            False, _window_display, extra="window", modules=("glfw",)),
    Backend("display", "openxr", "openxr[:egl|:xlib]", "a VR headset through its OpenXR runtime (SteamVR, Monado; "
            "docs/headset.md); OpenGL through EGL where the runtime offers it, else GLX on $DISPLAY, or as named",
            True, _openxr_display, extra="xr", modules=("xr",), takes_arg=None),
)


def backends(category: Category, registry: tuple[AnyBackend, ...] = BACKENDS) -> tuple[AnyBackend, ...]:
    """The registered backends of ``category``, in registry order.

    Examples
    --------
    >>> [b.usage for b in backends("tracker")][:2]
    ['sim', 'replay:FILE']
    """
    return tuple(b for b in registry if b.category == category)


def lookup(category: Category, spec: str, registry: tuple[AnyBackend, ...] = BACKENDS) -> tuple[AnyBackend, str]:
    """The backend ``spec`` (``NAME`` or ``NAME:ARG``) names, and its ``ARG``.

    An unknown name is one UserError (exit code 2) listing the registered ones.

    Examples
    --------
    >>> backend, arg = lookup("pose", "replay:data/s/sub-1/ses-1")
    >>> backend.name, arg
    ('replay', 'data/s/sub-1/ses-1')
    """
    name, _, arg = spec.partition(":")
    for backend in backends(category, registry):
        if backend.name == name:
            return backend, arg
    known = ", ".join(b.usage for b in backends(category, registry))
    raise UserError(f"unknown {category} {spec!r}; registered: {known}", OPTION[category])


@overload
def build(category: Literal["tracker"], spec: str, ctx: BackendContext,
          registry: tuple[AnyBackend, ...] = ...) -> GazeSource: ...
@overload
def build(category: Literal["pose"], spec: str, ctx: BackendContext,
          registry: tuple[AnyBackend, ...] = ...) -> PoseSource: ...
@overload
def build(category: Literal["responses"], spec: str, ctx: BackendContext,
          registry: tuple[AnyBackend, ...] = ...) -> ResponseSource: ...
@overload
def build(category: Literal["display"], spec: str, ctx: BackendContext,
          registry: tuple[AnyBackend, ...] = ...) -> Display: ...
def build(category: Category, spec: str, ctx: BackendContext,
          registry: tuple[AnyBackend, ...] = BACKENDS) -> GazeSource | PoseSource | ResponseSource | Display:
    """Look ``spec`` up, check its argument and optional dependency, and construct it: a tracker is a
    :class:`GazeSource`, a pose source a :class:`PoseSource`, responses a :class:`ResponseSource`, a display
    a :class:`Display` (the registry's entries of each kind make that type)."""
    backend, arg = lookup(category, spec, registry)
    backend.check_arg(spec, arg)
    backend.check_installed()
    return backend.make(arg, ctx)


def is_real_time(category: Category, spec: str, registry: tuple[AnyBackend, ...] = BACKENDS) -> bool:
    """Whether ``spec`` names a live device (its samples or presses are timed in real time)."""
    return lookup(category, spec, registry)[0].real_time


def help_text(category: Category, registry: tuple[AnyBackend, ...] = BACKENDS) -> str:
    """The ``--help`` text of ``category``'s option: every registered backend, its usage and summary.

    Examples
    --------
    >>> help_text("display").split(" | ")[0]
    'headless: no screen: frames are rendered off-screen (or only their cameras)'
    """
    parts = []
    for b in backends(category, registry):
        notes = [n for n in ("real time: needs --clock real" if b.real_time else "",
                             f"pip install 'psyop[{b.extra}]'" if b.extra and b.extra not in b.summary else "") if n]
        parts.append(f"{b.usage}: {b.summary}" + (f" ({'; '.join(notes)})" if notes else ""))
    return " | ".join(parts)
