"""Tracking through the OpenXR runtime of an ``--display openxr`` session: head and hand poses
(``--pose openxr[:HAND]``), eye gaze (``--tracker openxr``) and controller buttons
(``--responses openxr``). Each reads the runtime at the display time of the frame in progress
(:attr:`OpenXRDisplay.frame_time_ns`), after the display synced input for that frame, and each may
be combined with psyop's other backends (e.g. Pupil gaze with OpenXR head pose).

Frames: head poses are the VIEW space in the reference space (psyop's world: LOCAL, the head at
session start, gravity-aligned); hand poses are grip poses in the reference space; gaze is located
in the VIEW space (psyop's head space).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING

from psyop.session.rows import JsonObject, TrialRow
from psyop.errors import UserError
from psyop.session.gaze.sample import GazeSample, RawBuffer, RawGazeSample
from psyop.session.gaze.sync import ClockSync
from psyop.session.pose import PoseSample
from psyop.session.reach import horizontal_reach_m
from psyop.session.responses.base import RawInput, ResponseKindSpec
from psyop.devices.responses.keyboard import KeyboardResponses
from psyop.devices.xr.runtime import HANDS, XR_EXIT_CODE, rotate

if TYPE_CHECKING:
    from psyop.devices.xr.display import OpenXRDisplay
    from psyop.session.frames import Display
    from psyop.session.gaze.plan import FixationPlan


#: where the fixation is placed on the runtime's gaze ray (XR_EXT_eye_gaze_interaction gives a
#: direction, not a vergence distance); recorded in session.json with the tracker's stats
DEFAULT_GAZE_DISTANCE_M = 1.0


def _openxr_display(display: Display | None, option: str) -> OpenXRDisplay:
    from psyop.devices.xr.display import OpenXRDisplay

    if not isinstance(display, OpenXRDisplay):
        raise UserError(f"{option} openxr reads the headset's runtime: use it with --display openxr", option)
    return display


class OpenXRGaze:
    """A GazeSource from ``XR_EXT_eye_gaze_interaction``: the gaze pose in head space, with the
    runtime's own sample time (``XrEyeGazeSampleTimeEXT``) on the session clock. The fixation is
    the point ``distance_m`` along the gaze ray (the extension gives no vergence)."""

    def __init__(self, display: OpenXRDisplay, distance_m: float = DEFAULT_GAZE_DISTANCE_M) -> None:
        self.display = display
        self.runtime = display.runtime
        if self.runtime.gaze_space is None:
            raise UserError(f"{self.runtime.facts.runtime} ({self.runtime.facts.system}) offers no eye gaze "
                            "(XR_EXT_eye_gaze_interaction); use another --tracker (e.g. pupil:HOST:PORT)",
                            "--tracker openxr", XR_EXIT_CODE)
        self.distance_m = float(distance_m)
        self._n = self._invalid = self._untimed = 0
        self._raw = RawBuffer()
        self._last_raw_t_s = -math.inf

    @classmethod
    def on_display(cls, display: Display | None) -> "OpenXRGaze":
        return cls(_openxr_display(display, "--tracker"))

    def start(self) -> None:
        return None

    def set_plan(self, plan: FixationPlan) -> None:
        return None  # a person's eyes follow the stimulus, not a plan

    def clock_sync(self) -> ClockSync | None:
        """None: the runtime's sample times are mapped onto the session clock by the display."""
        return None

    def drain_raw(self) -> list[RawGazeSample]:
        """Each distinct gaze sample :meth:`latest` located (the runtime is polled once per frame)."""
        return self._raw.drain()

    def latest(self, now_s: float) -> GazeSample | None:
        t_ns = self.display.frame_time_ns
        if t_ns is None:
            return None
        xr, rt = self.runtime.xr, self.runtime
        sample_time = xr.EyeGazeSampleTimeEXT()
        pose = rt.locate(rt.gaze_space, rt.head, t_ns, next_struct=sample_time)
        self._n += 1
        if int(sample_time.time) > 0:
            t_s = self.display.to_session_s(int(sample_time.time))
        else:  # the runtime gave no sample time: the display time, counted
            t_s = self.display.to_session_s(t_ns)
            self._untimed += 1
        if not pose.valid:
            self._invalid += 1
            sample = GazeSample.invalid(t_s)
        else:
            dx, dy, dz = rotate(pose.orientation_wxyz, (0.0, 0.0, -1.0))
            ox, oy, oz = pose.position_m
            d = self.distance_m
            sample = GazeSample(t_s, (ox + d * dx, oy + d * dy, oz + d * dz), 1.0, True)
        if t_s > self._last_raw_t_s:
            self._last_raw_t_s = t_s
            self._raw.add(RawGazeSample.of(sample, tracker_t_s=float(sample_time.time) * 1e-9
                                           if int(sample_time.time) > 0 else math.nan, received_s=now_s))
        return sample

    def stats(self) -> JsonObject:
        return {"source": "openxr eye gaze (XR_EXT_eye_gaze_interaction)", "samples": self._n,
                "invalid": self._invalid, "without_sample_time": self._untimed,
                "fixation_distance_m": self.distance_m}

    def close(self) -> None:
        return None


class OpenXRPose:
    """A PoseSource from the runtime: the head every frame; the hand (a controller's grip or aim
    pose, or a Vive tracker's grip pose) sampled once per frame and kept for the reach."""

    n_reused_hand_trials = 0  # live: every trial's own hand samples

    def __init__(self, display: OpenXRDisplay, hand: str = "") -> None:
        self.display = display
        self.runtime = display.runtime
        self.hand_name = hand
        self._hand_space = None
        side, _, pose_kind = hand.partition(":")
        if side in HANDS and pose_kind in ("", "grip", "aim"):
            spaces = self.runtime.aim_spaces if pose_kind == "aim" else self.runtime.hand_spaces
            self._hand_space = spaces[side]
        elif side == "vive_tracker" and pose_kind:
            self._hand_space = self.runtime.tracker_space(pose_kind)
        elif hand:
            raise UserError(f"unknown OpenXR hand {hand!r}; use openxr, openxr:left, openxr:right (the grip pose), "
                            "openxr:left:aim, openxr:right:aim (the pointing pose) or openxr:vive_tracker:ROLE",
                            "--pose")
        self._hands: deque[PoseSample] = deque(maxlen=4096)
        self._last_frame_ns: int | None = None

    @classmethod
    def on_display(cls, display: Display | None, hand: str = "") -> "OpenXRPose":
        return cls(_openxr_display(display, "--pose"), hand)

    def head(self, now_s: float) -> PoseSample | None:
        pose = self.display.head_pose
        if pose is None:
            return None
        t_ns = self.display.frame_time_ns
        if self._hand_space is not None and t_ns is not None and t_ns != self._last_frame_ns:
            self._last_frame_ns = t_ns
            hand = self.runtime.locate(self._hand_space, self.runtime.world, t_ns)
            self._hands.append(PoseSample(self.display.to_session_s(t_ns), hand.position_m, hand.orientation_wxyz,
                                          hand.valid))
        return PoseSample(self.display.head_pose_time_s, pose.position_m, pose.orientation_wxyz, pose.valid)

    def hand(self, row: TrialRow, end_s: float, n: int, endpoint_m: Sequence[float] | None) -> list[PoseSample]:
        samples = [s for s in self._hands if s.timestamp_s <= end_s]
        return samples[-n:]

    def reach_m(self) -> float:
        """The newest hand sample's horizontal reach (NaN before any)."""
        if not self._hands:
            return math.nan
        return horizontal_reach_m(self._hands[-1].position_m)

    def close(self) -> None:
        return None


#: the raw input name of a controller's stick in a response kind's ``controller`` map (its value is the kind's
#: name for the deflection, e.g. an adjustment's "axis"); the select buttons are "left" and "right"
THUMBSTICK = "thumbstick"
#: the raw input name of a stick's sideways deflection (right positive; a rating's scale axis)
THUMBSTICK_X = "thumbstick_x"


class XrButtons:
    """Raw events from the controllers' select buttons, once per input sync: the left hand's is 'left', the
    right hand's 'right', each at the time the runtime saw the press (the response kind gives them meaning)."""

    def __init__(self, display: OpenXRDisplay) -> None:
        self.display, self.runtime = display, display.runtime
        self._seen_sync = -1
        #: the stick as the last :meth:`poll` saw it: (session time s of its last change, forward deflection)
        self.stick: tuple[float, float] = (0.0, 0.0)
        #: the same for the sideways deflection (right positive)
        self.stick_x: tuple[float, float] = (0.0, 0.0)

    def poll(self) -> list[tuple[str, float]]:
        rt = self.runtime
        if rt.sync_count == self._seen_sync or self.display.frame_time_ns is None:
            return []
        self._seen_sync = rt.sync_count
        presses = rt.select_presses()  # the runtime's own press times: a response time is not frame-quantised
        sticks = rt.thumbsticks()
        if sticks:  # the stick deflected furthest, when both hands hold one (forward and sideways apart)
            y, t_ns, _ = max(sticks.values(), key=lambda state: abs(state[0]))
            self.stick = self._changed(self.stick, y, t_ns)
            _, t_x_ns, x = max(sticks.values(), key=lambda state: abs(state[2]))
            self.stick_x = self._changed(self.stick_x, x, t_x_ns)
        events = sorted((self.display.to_session_s(t_ns), hand)
                        for hand, t_ns in presses.items())
        return [(name, t_s) for t_s, name in events[:1]]

    def _changed(self, last: tuple[float, float], value: float, t_ns: int) -> tuple[float, float]:
        """(time, deflection) after a poll that read ``value``: unchanged when it equals the last one. A runtime may
        report no change time (0, Monado on a return to rest): this sync's frame time stands for it."""
        if value == last[1]:
            return last
        assert self.display.frame_time_ns is not None  # poll returns before the first frame
        changed_s = self.display.to_session_s(t_ns if t_ns > 0 else self.display.frame_time_ns)
        return (max(changed_s, last[0]), value)


class OpenXRResponses(KeyboardResponses):
    """Answers from the controllers: XrButtons' 'left' / 'right' through the response kind's ``controller`` map
    (docs/protocols.md lists it); a reach is confirmed by either, its distance from the right controller's grip."""

    def __init__(self, events: XrButtons, kind: ResponseKindSpec, *, reach_m: Callable[[], float] | None = None,
                 keymap: Mapping[str, str] | None = None) -> None:
        super().__init__(events, kind, reach_m=reach_m, keymap=keymap)
        self._stick_phase_s = math.nan  # the response phase whose stick deflection was last reported
        self._stick_reported = {THUMBSTICK: 0.0, THUMBSTICK_X: 0.0}

    @classmethod
    def on_display(cls, built: Display | None, kind: ResponseKindSpec,
                   controller: Mapping[str, str] | None = None) -> "OpenXRResponses":
        display = _openxr_display(built, "--responses")
        display.needs_controller = True  # the first trial waits for one (OpenXRDisplay._wait_for_controller)

        def right_hand_reach_m() -> float:
            rt, t_ns = display.runtime, display.frame_time_ns
            if t_ns is None:
                return math.nan
            pose = rt.locate(rt.hand_spaces["right"], rt.world, t_ns)
            return horizontal_reach_m(pose.position_m) if pose.valid else math.nan

        keymap = kind.controller if controller is None else controller  # hand -> the kind's answer
        if not keymap:
            raise UserError(f"the controllers cannot give {kind.name} responses; use --responses keyboard with "
                            "--experimenter-window (its keys), or --responses serial:DEVICE", "--responses")
        return cls(XrButtons(display), kind, reach_m=right_hand_reach_m, keymap=keymap)

    def with_keymap(self, keymap: Mapping[str, str]) -> "OpenXRResponses":
        """The same controllers read through another map of their raw inputs (``left``, ``right``, ``thumbstick``,
        ``thumbstick_x``), e.g. a questionnaire item's scale whatever the trial's kind maps (psyop.session.screens);
        both read the one input sync, so only one of them is read at a time."""
        assert isinstance(self.events, XrButtons)
        return OpenXRResponses(self.events, self.kind, reach_m=self._reach_m, keymap=keymap)

    def raw_inputs(self, since_s: float, now_s: float) -> list[RawInput]:
        """The select buttons through the kind's map (as keys), and, where the map names ``thumbstick`` (forward)
        or ``thumbstick_x`` (sideways), the stick's deflection as that input (an adjustment's axis, a rating's scale
        axis) whenever it differs from the one last reported in this phase: a stick already held when the phase
        begins counts from the phase's start."""
        out = super().raw_inputs(since_s, now_s)
        if self._stick_phase_s != since_s:  # a new response phase: nothing reported yet (a resting stick reads 0)
            self._stick_phase_s, self._stick_reported = since_s, {THUMBSTICK: 0.0, THUMBSTICK_X: 0.0}
        assert isinstance(self.events, XrButtons)
        for raw_name, (changed_s, deflection) in ((THUMBSTICK, self.events.stick), (THUMBSTICK_X, self.events.stick_x)):
            axis = self.keymap.get(raw_name)
            if axis is not None and deflection != self._stick_reported[raw_name]:
                self._stick_reported[raw_name] = deflection
                out.append(RawInput(axis, max(changed_s, since_s), deflection))
        return sorted(out, key=lambda raw: raw.t_s)
