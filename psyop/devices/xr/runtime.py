"""One OpenXR runtime connection: instance, system, session, spaces, actions, events and time.

Everything psyop asks of an OpenXR runtime goes through :class:`XrRuntime`, built on pyopenxr
(``pip install 'psyop[xr]'``). The session's graphics binding is made from psyop's own moderngl
EGL context with ``XR_MNDX_egl_enable`` (headless on Linux: no window system needed). Runtimes
that offer only ``XR_KHR_opengl_enable`` with a window-system binding (GLX/Xlib, WGL) are refused
with a line naming the runtime: that binding is not implemented (docs/headset.md).

Spaces: the reference space (``LOCAL``: origin at the head at session start, gravity-aligned; or
``STAGE``) is psyop's world; the ``VIEW`` space is psyop's head space (x right, y up, -z forward,
origin between the eyes; docs/architecture.md). Poses come back as (position m, quaternion w, x,
y, z). Times: the runtime's ``XrTime`` (ns) is converted to the session clock through
``XR_KHR_convert_timespec_time`` (``CLOCK_MONOTONIC``, the clock psyop's RealClock reads on Linux).

Input: one action set holds the eye-gaze pose (``XR_EXT_eye_gaze_interaction``, when the system
supports it), each hand's grip pose and select button (khr/simple, htc/vive, valve/index and
oculus/touch bindings suggested; the aim pose too, for pointing), and Vive tracker grip poses (``XR_HTCX_vive_tracker_interaction``,
when offered). Actions are synced once per frame, only while the session is focused.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import math
import signal
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from types import ModuleType
from typing import TYPE_CHECKING, ParamSpec, TypeVar

from psyop.errors import UserError
from psyop.devices.xr.binding import BindingChoice, XrObject, current_binding
from psyop.optics.rotation import quaternion_multiply as quaternion_multiply, rotate as rotate  # the one implementation

if TYPE_CHECKING:
    import moderngl

T = TypeVar("T")
P = ParamSpec("P")

#: exit code of a headset runtime that is absent or fails (a device problem, not bad input)
XR_EXIT_CODE = 3
#: how long a runtime may take to reach the FOCUSED state before the session gives up
FOCUS_TIMEOUT_S = 60.0
#: with ``--responses openxr``: how long the session waits, before its first trial, for a controller
#: to be active (switched on, paired) before it ends with one line (exit 3)
CONTROLLER_TIMEOUT_S = 30.0

HANDS: tuple[str, ...] = ("left", "right")
_SELECT_BINDINGS = {
    "/interaction_profiles/khr/simple_controller": "select/click",
    "/interaction_profiles/htc/vive_controller": "trigger/click",
    "/interaction_profiles/valve/index_controller": "trigger/click",
    "/interaction_profiles/oculus/touch_controller": "trigger/value",
}
#: each profile's two-axis stick (the Vive wand's trackpad; the simple controller has none), the paths of the
#: OpenXR 1.0 specification's interaction profiles (section 6.4)
_THUMBSTICK_BINDINGS = {
    "/interaction_profiles/htc/vive_controller": "trackpad",
    "/interaction_profiles/valve/index_controller": "thumbstick",
    "/interaction_profiles/oculus/touch_controller": "thumbstick",
}


def xr_error(what: str, exc: BaseException | str, runtime: str = "the OpenXR runtime") -> UserError:
    """One line, exit 3: what failed, in which runtime, and where to look."""
    return UserError(f"{runtime}: {what}: {exc}; is a headset connected and its runtime (SteamVR, Monado) running? "
                     "XR_RUNTIME_JSON selects the runtime (docs/headset.md)", "--display openxr", XR_EXIT_CODE)


def import_xr() -> XrObject:
    """pyopenxr, or one line naming the extra that brings it."""
    try:
        import xr  # optional dependency, imported lazily
        import xr.raw_functions  # binds xr.raw_functions (xrGetSystemProperties, xrLocateSpace below)
    except ImportError as exc:
        raise UserError(f"--display openxr needs pyopenxr: pip install 'psyop[xr]' ({exc})", "--display",
                        XR_EXIT_CODE) from exc
    return xr


@dataclass(frozen=True)
class XrPose:
    """A located pose: position (m) and unit quaternion (w, x, y, z) in the base space; ``valid``
    when the runtime says both are valid and the orientation is tracked."""

    position_m: tuple[float, float, float]
    orientation_wxyz: tuple[float, float, float, float]
    valid: bool


@dataclass
class RuntimeFacts:
    """What session.json records of the runtime."""

    runtime: str = ""
    system: str = ""
    extensions: list[str] = field(default_factory=list)
    eye_gaze_supported: bool = False
    vive_trackers: bool = False
    recommended_sizes_px: list[tuple[int, int]] = field(default_factory=list)
    reference_space: str = "local"
    graphics: str = ""  # the OpenGL binding: egl (XR_MNDX_egl_enable) or xlib (GLX on an X display)
    states: list[str] = field(default_factory=list)


def _pose(xr: ModuleType, location: XrObject, valid_bits: int) -> XrPose:
    p, q = location.pose.position, location.pose.orientation
    flags = int(location.location_flags)
    return XrPose((float(p.x), float(p.y), float(p.z)), (float(q.w), float(q.x), float(q.y), float(q.z)),
                  (flags & valid_bits) == valid_bits)


_HELD_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class _Held:
    """Per-process nesting depth of :func:`runtime_threads_without_signals` (main thread only)."""

    depth = 0


@contextlib.contextmanager
def runtime_threads_without_signals() -> Iterator[None]:
    """Hold SIGINT, SIGTERM and SIGHUP while this thread is inside the runtime: at the OS level
    (the mask, which the runtime's own threads inherit) and at Python's (each signal's handler runs
    after the section, not inside it). The outermost section restores both and then runs the
    handlers of the signals that arrived, so Ctrl-C still raises, between two runtime calls.

    Two faults it prevents, both found by test_ctrl_c_mid_frame_ends_the_headset_session_cleanly_
    and_it_resumes under load: a KeyboardInterrupt raised just after ``xrWaitFrame`` returned left
    a frame that was neither begun nor ended, and the next ``xrWaitFrame`` (in teardown) blocked
    for ever; a signal delivered to one of an in-process runtime's threads interrupts its waits."""
    if threading.current_thread() is not threading.main_thread() or _Held.depth:
        _Held.depth += 1
        try:
            yield
        finally:
            _Held.depth -= 1
        return
    arrived: list[int] = []
    previous_handlers = {}
    for signum in _HELD_SIGNALS:
        handler = signal.getsignal(signum)
        if callable(handler):
            previous_handlers[signum] = handler
            signal.signal(signum, lambda n, frame: arrived.append(n))
    previous_mask = signal.pthread_sigmask(signal.SIG_BLOCK, set(_HELD_SIGNALS))
    _Held.depth = 1
    try:
        yield
    finally:
        _Held.depth = 0
        signal.pthread_sigmask(signal.SIG_SETMASK, previous_mask)  # a held signal is delivered now
        for signum, handler in previous_handlers.items():
            signal.signal(signum, handler)
        for number in dict.fromkeys(arrived):
            previous_handlers[signal.Signals(number)](number, None)


def signals_held(method: Callable[P, T]) -> Callable[P, T]:
    """A method that calls into the runtime, run with the signals held (see above)."""

    @functools.wraps(method)
    def held(*args: P.args, **kwargs: P.kwargs) -> T:
        with runtime_threads_without_signals():
            return method(*args, **kwargs)

    return held


def runtime_extensions(xr: ModuleType) -> set[str]:
    """The instance extensions the active runtime offers; no runtime is a one-line error (exit 3)."""
    try:
        return {_text(e.extension_name) for e in xr.enumerate_instance_extension_properties()}
    except Exception as exc:  # re-raised as a one-line UserError: the loader finds no runtime
        raise xr_error("no OpenXR runtime could be loaded", exc) from exc


class XrRuntime:
    """Instance, system and session of the runtime, bound to ``ctx`` (a moderngl EGL context)."""

    def __init__(self, ctx: moderngl.Context, binding: BindingChoice, *, reference_space: str = "local",
                 app_name: str = "psyop") -> None:
        self.xr = import_xr()
        self.instance = self.system = self.session = None
        self._spaces: list[XrObject] = []
        try:
            with runtime_threads_without_signals():
                self._open(ctx, binding, reference_space, app_name)
        except BaseException:
            # a Ctrl-C held during the start is raised as the section ends: the runtime must not
            # outlive it (an instance left open crashed the interpreter's exit, -11, under load)
            self.close()
            raise

    def _open(self, ctx: moderngl.Context, binding: BindingChoice, reference_space: str, app_name: str) -> None:
        xr = self.xr
        self.ctx = ctx
        self.graphics = binding
        self.facts = RuntimeFacts(reference_space=reference_space, graphics=binding.api)
        self.instance = self.system = self.session = None
        self._spaces = []
        self.state = xr.SessionState.UNKNOWN
        self.running = False
        self._lost = ""
        self.sync_count = 0  # input syncs so far (a press is reported once per sync)
        available = runtime_extensions(xr)
        wanted = ["XR_KHR_convert_timespec_time", "XR_EXT_eye_gaze_interaction", "XR_HTCX_vive_tracker_interaction"]
        enable = list(binding.extensions) + [e for e in wanted if e in available]
        if "XR_KHR_convert_timespec_time" not in enable:
            raise xr_error("the runtime cannot convert its times to CLOCK_MONOTONIC (XR_KHR_convert_timespec_time)",
                           "unsupported")
        self.facts.extensions = enable
        try:
            self.instance = xr.create_instance(xr.InstanceCreateInfo(
                application_info=xr.ApplicationInfo(application_name=app_name, engine_name="psyop",
                                                    api_version=xr.Version(1, 0, 0)),
                enabled_extension_names=enable))
            props = xr.get_instance_properties(self.instance)
            self.facts.runtime = f"{_text(props.runtime_name)} {xr.Version(props.runtime_version)}"
            self.system = xr.get_system(self.instance, xr.SystemGetInfo(form_factor=xr.FormFactor.HEAD_MOUNTED_DISPLAY))
        except Exception as exc:  # re-raised as a one-line UserError after closing
            self.close()
            raise xr_error("no headset (HMD system) is available", exc, self.facts.runtime or "the OpenXR runtime") from exc
        try:
            self._create_session(enable)
        except UserError:
            self.close()
            raise
        except Exception as exc:  # re-raised as a one-line UserError after closing
            self.close()
            raise xr_error("creating the session failed", exc, self.facts.runtime) from exc

    # -- set-up ---------------------------------------------------------------------------------
    def _create_session(self, enable: list[str]) -> None:
        xr = self.xr
        gaze_props = xr.SystemEyeGazeInteractionPropertiesEXT()
        sprops = xr.SystemProperties(next=gaze_props if "XR_EXT_eye_gaze_interaction" in enable else None)
        xr.raw_functions.xrGetSystemProperties(self.instance, self.system, ctypes.byref(sprops))
        self.facts.system = _text(sprops.system_name)
        self.facts.eye_gaze_supported = bool(gaze_props.supports_eye_gaze_interaction)
        self.facts.vive_trackers = "XR_HTCX_vive_tracker_interaction" in enable
        self.view_config = xr.ViewConfigurationType.PRIMARY_STEREO
        views = xr.enumerate_view_configuration_views(self.instance, self.system, self.view_config)
        self.facts.recommended_sizes_px = [(int(v.recommended_image_rect_width), int(v.recommended_image_rect_height))
                                           for v in views]
        xr.get_opengl_graphics_requirements_khr(self.instance, self.system)  # required before xrCreateSession
        binding = current_binding(xr, self.graphics.api)
        if isinstance(binding, str):
            raise xr_error(binding, "no graphics binding", self.facts.runtime)
        self.session = xr.create_session(self.instance, xr.SessionCreateInfo(system_id=self.system,
                                                                             next=binding.pointer()))
        self._binding = binding  # the runtime keeps pointers into it
        space_type = {"local": xr.ReferenceSpaceType.LOCAL, "stage": xr.ReferenceSpaceType.STAGE}[self.facts.reference_space]
        self.world = self._reference_space(space_type)
        self.head = self._reference_space(xr.ReferenceSpaceType.VIEW)
        self._create_actions()

    def _reference_space(self, kind: XrObject) -> XrObject:
        xr = self.xr
        space = xr.create_reference_space(self.session, xr.ReferenceSpaceCreateInfo(
            reference_space_type=kind, pose_in_reference_space=xr.Posef()))
        self._spaces.append(space)
        return space

    def _path(self, text: str) -> XrObject:
        return self.xr.string_to_path(self.instance, text)

    def _suggest_controller_bindings(self) -> None:
        """Each controller profile's grip and aim poses, select button and (where it has one) stick, suggested in one
        call per profile (a runtime that rejects one path drops that profile's whole suggestion: tested on Monado's
        Index profile, tests/devices/xr/test_openxr_thumbstick.py)."""
        xr = self.xr
        for profile, button in _SELECT_BINDINGS.items():
            bindings = []
            for h in HANDS:
                bindings.append(xr.ActionSuggestedBinding(self.grip, self._path(f"/user/hand/{h}/input/grip/pose")))
                bindings.append(xr.ActionSuggestedBinding(self.aim, self._path(f"/user/hand/{h}/input/aim/pose")))
                bindings.append(xr.ActionSuggestedBinding(self.select, self._path(f"/user/hand/{h}/input/{button}")))
                if profile in _THUMBSTICK_BINDINGS:
                    bindings.append(xr.ActionSuggestedBinding(
                        self.stick, self._path(f"/user/hand/{h}/input/{_THUMBSTICK_BINDINGS[profile]}")))
            try:
                xr.suggest_interaction_profile_bindings(self.instance, xr.InteractionProfileSuggestedBinding(
                    interaction_profile=self._path(profile), suggested_bindings=bindings))
            except xr.exception.XrException:
                pass  # a runtime may not know every profile; the others still bind

    def _create_actions(self) -> None:
        xr = self.xr
        self.action_set = xr.create_action_set(self.instance, xr.ActionSetCreateInfo(
            action_set_name="psyop", localized_action_set_name="psyop", priority=0))
        hands = [self._path(f"/user/hand/{h}") for h in HANDS]
        self.hand_paths = dict(zip(HANDS, hands))
        self.grip = xr.create_action(self.action_set, xr.ActionCreateInfo(
            action_type=xr.ActionType.POSE_INPUT, action_name="hand_grip", localized_action_name="Hand grip",
            subaction_paths=hands))
        self.aim = xr.create_action(self.action_set, xr.ActionCreateInfo(
            action_type=xr.ActionType.POSE_INPUT, action_name="hand_aim", localized_action_name="Hand aim",
            subaction_paths=hands))
        self.select = xr.create_action(self.action_set, xr.ActionCreateInfo(
            action_type=xr.ActionType.BOOLEAN_INPUT, action_name="select", localized_action_name="Select",
            subaction_paths=hands))
        self.stick = xr.create_action(self.action_set, xr.ActionCreateInfo(
            action_type=xr.ActionType.VECTOR2F_INPUT, action_name="thumbstick", localized_action_name="Thumbstick",
            subaction_paths=hands))
        self._suggest_controller_bindings()
        self.gaze_action = None
        if self.facts.eye_gaze_supported:
            self.gaze_action = xr.create_action(self.action_set, xr.ActionCreateInfo(
                action_type=xr.ActionType.POSE_INPUT, action_name="eye_gaze", localized_action_name="Eye gaze"))
            xr.suggest_interaction_profile_bindings(self.instance, xr.InteractionProfileSuggestedBinding(
                interaction_profile=self._path("/interaction_profiles/ext/eye_gaze_interaction"),
                suggested_bindings=[xr.ActionSuggestedBinding(self.gaze_action,
                                                              self._path("/user/eyes_ext/input/gaze_ext/pose"))]))
        self.tracker_action = None
        self.tracker_roles: dict[str, XrObject] = {}
        if self.facts.vive_trackers:  # XR_HTCX_vive_tracker_interaction: grip poses by role
            roles = ["handheld_object", "left_foot", "right_foot", "left_shoulder", "right_shoulder", "left_elbow",
                     "right_elbow", "left_knee", "right_knee", "waist", "chest", "camera", "keyboard"]
            self.tracker_roles = {r: self._path(f"/user/vive_tracker_htcx/role/{r}") for r in roles}
            self.tracker_action = xr.create_action(self.action_set, xr.ActionCreateInfo(
                action_type=xr.ActionType.POSE_INPUT, action_name="tracker_grip", localized_action_name="Tracker",
                subaction_paths=list(self.tracker_roles.values())))
            try:
                xr.suggest_interaction_profile_bindings(self.instance, xr.InteractionProfileSuggestedBinding(
                    interaction_profile=self._path("/interaction_profiles/htc/vive_tracker_htcx"),
                    suggested_bindings=[xr.ActionSuggestedBinding(
                        self.tracker_action, self._path(f"/user/vive_tracker_htcx/role/{r}/input/grip/pose"))
                        for r in roles]))
            except xr.exception.XrException:
                self.tracker_action = None
        xr.attach_session_action_sets(self.session, xr.SessionActionSetsAttachInfo(action_sets=[self.action_set]))
        self.hand_spaces = {h: self._action_space(self.grip, self.hand_paths[h]) for h in HANDS}
        self.aim_spaces = {h: self._action_space(self.aim, self.hand_paths[h]) for h in HANDS}
        self.gaze_space = self._action_space(self.gaze_action, xr.NULL_PATH) if self.gaze_action is not None else None

    def _action_space(self, action: XrObject, subaction: XrObject) -> XrObject:
        xr = self.xr
        space = xr.create_action_space(self.session, xr.ActionSpaceCreateInfo(
            action=action, subaction_path=subaction, pose_in_action_space=xr.Posef()))
        self._spaces.append(space)
        return space

    @signals_held
    def tracker_space(self, role: str) -> XrObject:
        """The grip space of the Vive tracker with this role (XR_HTCX_vive_tracker_interaction)."""
        if self.tracker_action is None:
            raise xr_error("no Vive tracker poses", "the runtime does not offer XR_HTCX_vive_tracker_interaction",
                           self.facts.runtime)
        if role not in self.tracker_roles:
            raise UserError(f"unknown Vive tracker role {role!r}; use one of {', '.join(self.tracker_roles)}", "--pose")
        return self._action_space(self.tracker_action, self.tracker_roles[role])

    # -- session state ----------------------------------------------------------------------------
    @signals_held
    def poll_events(self) -> None:
        """Drain the runtime's events; follow the session state (begin the session when READY,
        end it when STOPPING). A change that takes the session out of focus ends the drain, so the
        trial in progress is interrupted for the focus loss itself (the events after it are read on
        the next poll, in order)."""
        xr = self.xr
        while True:
            try:
                event = xr.poll_event(self.instance)
            except xr.EventUnavailable:
                return
            kind = xr.StructureType(event.type)
            if kind == xr.StructureType.EVENT_DATA_SESSION_STATE_CHANGED:
                changed = ctypes.cast(ctypes.byref(event), ctypes.POINTER(xr.EventDataSessionStateChanged)).contents
                was_focused = self.state == xr.SessionState.FOCUSED
                self.state = xr.SessionState(changed.state)
                self.facts.states.append(self.state.name)
                if self.state == xr.SessionState.READY and not self.running:
                    xr.begin_session(self.session, xr.SessionBeginInfo(self.view_config))
                    self.running = True
                elif self.state == xr.SessionState.STOPPING and self.running:
                    xr.end_session(self.session)
                    self.running = False
                    self._lost = self._lost or "the runtime is stopping the session (STOPPING)"
                elif self.state in (xr.SessionState.LOSS_PENDING, xr.SessionState.EXITING):
                    self._lost = self._lost or f"the runtime ended the session ({self.state.name})"
                if was_focused and self.state != xr.SessionState.FOCUSED:
                    return  # the focus loss interrupts the trial before later events are read
            elif kind == xr.StructureType.EVENT_DATA_INSTANCE_LOSS_PENDING:
                self._lost = self._lost or "the runtime is going away (instance loss pending)"

    @property
    def focused(self) -> bool:
        return self.running and self.state == self.xr.SessionState.FOCUSED

    @property
    def lost(self) -> str:
        """Why the session cannot go on ('' while it can)."""
        return self._lost

    # -- time ---------------------------------------------------------------------------------------
    @signals_held
    def xr_time_now_ns(self) -> int:
        """The runtime's XrTime of CLOCK_MONOTONIC now, and the monotonic reading it came from."""
        xr = self.xr
        mono_ns = time.clock_gettime_ns(time.CLOCK_MONOTONIC)
        spec = xr.timespec(mono_ns // 1_000_000_000, mono_ns % 1_000_000_000)
        fn = ctypes.cast(xr.get_instance_proc_addr(self.instance, "xrConvertTimespecTimeToTimeKHR"),
                         xr.PFN_xrConvertTimespecTimeToTimeKHR)
        out = xr.Time()
        result = xr.check_result(fn(self.instance, ctypes.byref(spec), ctypes.byref(out)))
        if result.is_exception():
            raise result
        return int(out.value) - mono_ns  # offset: XrTime = CLOCK_MONOTONIC ns + offset

    # -- locating -------------------------------------------------------------------------------------
    @signals_held
    def locate(self, space: XrObject, base: XrObject, xr_time_ns: int, next_struct: XrObject = None) -> XrPose:
        xr = self.xr
        location = xr.SpaceLocation(next=next_struct)
        xr.raw_functions.xrLocateSpace(space, base, xr_time_ns, ctypes.byref(location))
        bits = int(xr.SpaceLocationFlags.POSITION_VALID_BIT | xr.SpaceLocationFlags.ORIENTATION_VALID_BIT
                   | xr.SpaceLocationFlags.ORIENTATION_TRACKED_BIT)
        return _pose(xr, location, bits)

    @signals_held
    def sync_actions(self) -> None:
        """Sync input once per frame (only delivered while focused)."""
        xr = self.xr
        if not self.focused:
            return
        try:
            xr.sync_actions(self.session, xr.ActionsSyncInfo(active_action_sets=[xr.ActiveActionSet(self.action_set,
                                                                                                    xr.NULL_PATH)]))
        except xr.SessionNotFocused:
            return
        self.sync_count += 1

    @signals_held
    def active_controllers(self) -> tuple[str, ...]:
        """The hands with a controller bound now (a current interaction profile, known after a sync)."""
        xr = self.xr
        active = []
        for hand, path in self.hand_paths.items():
            try:
                state = xr.get_current_interaction_profile(self.session, path)
            except xr.XrException:
                continue
            if state.interaction_profile != xr.NULL_PATH:
                active.append(hand)
        return tuple(active)

    @signals_held
    def select_presses(self) -> dict[str, int]:
        """Per hand whose select button went down since the last sync: the runtime's time of the
        press (``lastChangeTime``, XrTime ns)."""
        xr = self.xr
        out = {}
        for hand, path in self.hand_paths.items():
            state = xr.get_action_state_boolean(self.session, xr.ActionStateGetInfo(action=self.select,
                                                                                     subaction_path=path))
            if state.is_active and state.current_state and state.changed_since_last_sync:
                out[hand] = int(state.last_change_time)
        return out

    @signals_held
    def thumbsticks(self) -> dict[str, tuple[float, int, float]]:
        """Per hand with an active stick: its forward deflection now (y in [-1, 1], forward positive), the
        runtime's time of its last change (``lastChangeTime``, XrTime ns) and its sideways deflection (x in [-1, 1],
        right positive)."""
        xr = self.xr
        out = {}
        for hand, path in self.hand_paths.items():
            state = xr.get_action_state_vector2f(self.session, xr.ActionStateGetInfo(action=self.stick,
                                                                                      subaction_path=path))
            if state.is_active:
                out[hand] = (float(state.current_state.y), int(state.last_change_time), float(state.current_state.x))
        return out

    # -- teardown -------------------------------------------------------------------------------------
    @signals_held
    def request_exit(self, pump_frame: XrObject, timeout_s: float = 5.0) -> None:
        """``xrRequestExitSession`` and follow the states to the end (the runtime only moves on while
        frames are submitted: ``pump_frame()`` submits an empty one)."""
        xr = self.xr
        if self.session is None or not self.running:
            return
        try:
            xr.request_exit_session(self.session)
        except xr.exception.XrException:
            return
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            self.poll_events()
            if not self.running or self.state in (xr.SessionState.EXITING, xr.SessionState.IDLE):
                return
            try:
                pump_frame()
            except xr.exception.XrException:
                return

    @signals_held
    def close(self) -> None:
        xr = self.xr
        for space in self._spaces:
            try:
                xr.destroy_space(space)
            except Exception:  # noqa: BLE001 - teardown goes on
                pass
        self._spaces = []
        if self.session is not None:
            try:
                xr.destroy_session(self.session)
            except Exception:  # noqa: BLE001
                pass
            self.session = None
        if self.instance is not None:
            try:
                xr.destroy_instance(self.instance)
            except Exception:  # noqa: BLE001
                pass
            self.instance = None


def _text(value: XrObject) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


def tangents_from_fov(fov: XrObject) -> tuple[float, float, float, float]:
    """OpenXR's XrFovf angles (radians; left and down negative) as (left, right, bottom, top) tangents."""
    return (math.tan(fov.angle_left), math.tan(fov.angle_right), math.tan(fov.angle_down), math.tan(fov.angle_up))
