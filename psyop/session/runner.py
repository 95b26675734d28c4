"""Assemble a session (clock, gaze, responses, renderer, display, store) and run it.

This is what ``psyop run`` and ``psyop simulate`` call. Everything a session used is
recorded in its session.json: protocol text and hash, seed, package versions, eye
model, display, tracker clock-sync, host.
"""

from __future__ import annotations

import functools
import importlib.metadata
import platform
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from psyop.errors import UserError
from psyop.protocol.model import Protocol
from psyop.session.clock import RealClock, VirtualClock
from psyop.session.frames import CameraRenderer, Display, HeadlessDisplay
from psyop.session.gaze.simulated import SimulatedTracker, SimulatedTrackerConfig, seed_for
from psyop.session.log.layout import session_paths, write_dataset_description
from psyop.session.log.schema import trial_schema
from psyop.adaptive.session import AdaptiveLevels, add_log_columns
from psyop.session.log.store import SessionStore, recover_tables
from psyop.session.loop import LoopConfig, SessionOutcome, TrialLoop
from psyop.session.plan import DEFAULT_IPD_M, SessionPlan, compile_plan
from psyop.session.resume import accept_protocol_change, check_options, resolve_seed
from psyop.session.responses.simulated import make_observer

__all__ = ["DEFAULT_IPD_M", "SessionOptions", "print_outcome", "run_session"]
_PACKAGES = ("psyop", "numpy", "scipy", "pandas", "pyarrow", "pydantic", "pyzmq", "pyserial", "msgpack", "moderngl", "tqdm")


@dataclass(frozen=True)
class SessionOptions:
    """Command-line choices of one session (see ``psyop run --help``)."""

    participant: str
    session: int = 1
    seed: int | None = None
    tracker: str = "sim"
    responses: str = "sim"
    display: str = "headless"
    clock: str = "virtual"
    data_root: Path = Path("data")
    progress: bool = True
    phase_delay_s: float = 0.0
    tracker_faults: SimulatedTrackerConfig = field(default_factory=SimulatedTrackerConfig)
    write_description: bool = True
    fsync: bool = True
    every_frame: bool | None = None  # None: every frame unless virtual clock + observer without images
    render: str = "auto"  # auto | images | cameras (see docs/sessions.md)
    check_scale: float = 0.25  # resolution of the sampled check frames of headless simulated sessions
    check_images: int = 2  # images rendered and checked per headless simulated session
    window_scale: float = 0.25  # window size as a fraction of the display profile's pixels
    allow_protocol_change: bool = False  # resume with a protocol edited only in comments (resume.py)
    pose: str = "sim"  # sim | replay:SESSION_DIR (head and hand pose; docs/sessions.md)
    xr_request_exit_at_frame: int | None = None  # testing aid: the OpenXR runtime is asked to stop at frame N
    participant_index: int | None = None  # keys block_order: latin_square (None: the number the ID ends in)

    @property
    def simulated(self) -> bool:
        """No person took part: simulated gaze, and a simulated observer or nobody answering."""
        return self.tracker == "sim" and self.responses in ("sim", "none")


def package_versions() -> dict[str, str]:
    """Installed versions of the packages a session depends on (read once per process: the
    metadata scan costs ~50 ms, and installed versions do not change under a running process)."""
    return dict(_package_versions())


@functools.cache
def _package_versions() -> tuple[tuple[str, str], ...]:
    versions = []
    for name in _PACKAGES:
        try:
            versions.append((name, importlib.metadata.version(name)))
        except importlib.metadata.PackageNotFoundError:
            versions.append((name, "not installed"))
    return tuple(versions)


def _make_gaze(spec: str, clock: Any, seed: int, faults: SimulatedTrackerConfig, display: Display) -> Any:
    kind, _, arg = spec.partition(":")
    if kind == "sim":
        return SimulatedTracker(seed_for(seed, "tracker"), faults)
    if kind == "replay":
        from psyop.session.gaze.replay import ReplayTracker

        return ReplayTracker.from_path(Path(arg))
    if clock.virtual:
        raise UserError(f"--tracker {kind} is a live device; use --clock real with it", "--clock")
    if kind == "pupil":
        from psyop.session.gaze.pupil import PupilClient

        host, _, port = arg.rpartition(":")
        if not host or not port.isdigit():
            raise UserError(f"expected pupil:HOST:PORT, got {spec!r}", "--tracker")
        return PupilClient(host, int(port), clock=clock.now_s)
    if kind == "openxr":
        from psyop.session.xr.tracking import OpenXRGaze

        return OpenXRGaze.on_display(display)
    if kind == "serial":
        from psyop.session.gaze.serial_source import SerialGazeSource

        if not arg:
            raise UserError("expected serial:DEVICE", "--tracker")
        return SerialGazeSource(arg, clock=clock.now_s)
    raise UserError(f"unknown tracker {spec!r}; use sim, replay:FILE, pupil:HOST:PORT, serial:DEVICE or openxr", "--tracker")


def _make_pose(spec: str, seed: int, protocol_sha256: str = "", schedule: pd.DataFrame | None = None,
               display: Display | None = None) -> Any:
    """The head/hand pose source: simulated (from the seed) or replayed from a logged session
    (checked against this session's schedule: psyop.session.pose_replay.pair_trials)."""
    kind, _, arg = spec.partition(":")
    if kind == "sim" and not arg:
        from psyop.session.pose import SimulatedPose

        return SimulatedPose(seed_for(seed, "pose"))
    if kind in ("replay", "replay-by-condition"):
        from psyop.session.pose_replay import ReplayPose, ReplaySchedule

        if not arg:
            raise UserError(f"expected {kind}:SESSION_DIR", "--pose")
        target = None if schedule is None else ReplaySchedule(
            protocol_sha256, seed, tuple(schedule["condition"].astype(str)) if "condition" in schedule else ())
        return ReplayPose.from_path(Path(arg), target, by_condition=kind == "replay-by-condition")
    if kind == "openxr":
        from psyop.session.xr.tracking import OpenXRPose

        return OpenXRPose.on_display(display, arg)
    raise UserError(f"unknown pose source {spec!r}; use sim, replay:SESSION_DIR, replay-by-condition:SESSION_DIR, "
                    "openxr or openxr:HAND_PATH", "--pose")


def _make_responses(spec: str, plan: SessionPlan, seed: int, participant: str, clock: Any, window: Any,
                    display: Display | None = None) -> Any:
    name, _, arg = spec.partition(":")
    kind = plan.kind
    if name == "sim":
        params = plan.observer_params()
        if params is None:
            raise UserError("--responses sim needs an observer: section in the protocol", "protocol")
        return make_observer(params, seed=seed, participant=participant)
    if name == "none":
        if plan.response.timeout_s is None:
            raise UserError("--responses none: nobody answers, and the protocol's response phase has no timeout_s, "
                            "so the session would wait forever; add timeout_s to it or use --responses sim",
                            "--responses")
        from psyop.session.responses.none import NoResponses

        return NoResponses()
    if name == "serial":
        from psyop.session.responses.serial_box import SerialResponseBox

        try:
            return SerialResponseBox(arg, kind, clock=clock.now_s)
        except (ValueError, ConnectionError) as exc:
            raise UserError(str(exc), "--responses") from exc
    if name == "keyboard":
        if window is None:
            raise UserError("--responses keyboard needs --display window", "--responses")
        from psyop.session.responses.keyboard import KeyboardResponses

        return KeyboardResponses(window, kind)
    if name == "openxr":
        from psyop.session.xr.tracking import OpenXRResponses

        return OpenXRResponses.on_display(display, kind)
    raise UserError(f"unknown response source {spec!r}; use sim, keyboard, serial:DEVICE, openxr or none", "--responses")


def _make_display(options: SessionOptions, plan: SessionPlan, clock: Any) -> Display:
    """Where the session's frames go (psyop.session.frames.Display): headless, a window or an
    OpenXR headset."""
    if options.display == "headless":
        return HeadlessDisplay(clock, float(plan.display.refresh_hz))
    if options.display == "window":
        from psyop.session.window import GlfwWindow

        return GlfwWindow(plan.display, clock, scale=options.window_scale, n_eyes=len(plan.rig.eyes))
    if options.display == "openxr":
        if clock.virtual:
            raise UserError("--display openxr shows frames to a person in real time; use --clock real with it",
                            "--clock")
        from psyop.session.xr.display import open_openxr_display

        return open_openxr_display(plan, clock, options.xr_request_exit_at_frame)
    raise UserError(f"unknown display {options.display!r}; use headless, window or openxr", "--display")


def _window_type() -> type:
    from psyop.session.window import GlfwWindow

    return GlfwWindow


def _make_renderer(mode: str, plan: SessionPlan, display: Display, window_scale: float, scale: float,
                   max_images: int | None) -> tuple[Any, str]:
    """The frame renderer and a description of it for session.json.

    'images': the protocol's stimulus ray-cast by psyop.rendering (needs OpenGL/EGL);
    'cameras': only the gaze-dependent eye cameras; 'auto': images if a context can be
    created, else cameras (recorded, never silent). A display with its own OpenGL context (a
    window, a headset) is rendered in that context, every frame watched.
    """
    if mode not in ("auto", "images", "cameras"):
        raise UserError(f"unknown render mode {mode!r}; use auto, images or cameras", "--render")
    if mode == "cameras":
        return CameraRenderer(plan.display, plan.rig), "cameras only"
    from psyop.session.scene_renderer import WATCHED_CHECK_EVERY, SceneRenderer

    if display.gl_context is not None:
        scale_used = window_scale if display.name == "window" else 1.0
        where = "in the window" if display.name == "window" else f"in the {display.name} display's swapchain images"
        return (SceneRenderer(plan, scale=scale_used, ctx=display.gl_context, owns_ctx=False,
                              check_every=WATCHED_CHECK_EVERY),
                f"images at scale {scale_used:g} {where}, each eye's first and every {WATCHED_CHECK_EVERY}th rendered "
                "image checked")
    try:
        from psyop.rendering.renderer import create_headless_context

        ctx = create_headless_context()
    except Exception as exc:  # noqa: BLE001 - any OpenGL/EGL failure
        if mode == "images":
            raise UserError(f"cannot create an OpenGL context for rendering: {exc}", "--render") from exc
        return CameraRenderer(plan.display, plan.rig), f"cameras only (no OpenGL context: {exc})"
    limit = (f"every stimulus frame, each eye's first and every {WATCHED_CHECK_EVERY}th rendered image checked"
             if max_images is None else f"first {max_images} stimulus frames checked")
    return (SceneRenderer(plan, scale=scale, ctx=ctx, max_images=max_images,
                          check_every=WATCHED_CHECK_EVERY if max_images is None else 1),
            f"images at scale {scale:g}, {limit}")


def run_session(
    protocol: Protocol,
    compile_schedule: Callable[[Protocol, int], pd.DataFrame],
    options: SessionOptions,
) -> SessionOutcome:
    """Run (or resume) one session to the end of its schedule, or to a clean stop.

    The protocol is compiled into a :class:`~psyop.session.plan.SessionPlan` first; everything
    below runs from the plan."""
    plan = compile_plan(protocol)
    study = plan.study
    paths = session_paths(options.data_root, study, options.participant, options.session)
    check_options(clock=options.clock, responses=options.responses, tracker=options.tracker)
    seed = resolve_seed(paths, options.seed, seed_for(study, options.participant, options.session))
    protocol_sha256 = accept_protocol_change(paths, protocol) if options.allow_protocol_change \
        else protocol.source_sha256
    from psyop.schedule.counterbalance import block_sequence, resolve_participant_index
    from psyop.session.log.store import read_metadata

    recorded = (read_metadata(paths) or {}).get("participant_index")
    participant_index = resolve_participant_index(options.participant_index, options.participant,
                                                  recorded if isinstance(recorded, int) else None)
    schedule = compile_schedule(protocol, seed, participant_index=participant_index)
    if plan.adaptive is not None:  # the adaptive level and the procedure's state are logged per trial
        schedule = add_log_columns(schedule, plan.adaptive)
    display_profile = plan.display

    if options.clock == "virtual":
        clock: Any = VirtualClock()
    elif options.clock == "real":
        clock = RealClock()
    else:
        raise UserError(f"unknown clock {options.clock!r}; use virtual or real", "--clock")

    store = SessionStore(paths, trial_schema(schedule), fsync=options.fsync)
    metadata = {
        "study": study, "participant": options.participant, "session": options.session, "seed": seed,
        "simulated": options.simulated, "protocol_sha256": protocol_sha256,
        "protocol_file_sha256": protocol.source_sha256,
        "protocol_text": protocol.source_text, "protocol_file": protocol.source_name,
        "n_trials_scheduled": int(len(schedule)), **plan.metadata(), "packages": package_versions(),
        "participant_index": participant_index,
        "block_order": {"kind": protocol.design.randomisation.block_order,
                        "blocks": block_sequence(schedule, protocol.design.randomisation.by)}
        if protocol.design.randomisation.kind == "blocked" else None,
        "python": platform.python_version(), "host": platform.node(),
        "tracker": options.tracker, "responses": options.responses,
        "display_mode": options.display, "clock": options.clock,
    }
    metadata["pose"] = options.pose
    renderer: Any = None
    display = _make_display(options, plan, clock)
    pose = _make_pose(options.pose, seed, protocol.source_sha256, schedule, display)
    gaze = _make_gaze(options.tracker, clock, seed, options.tracker_faults, display)
    window = display if isinstance(display, _window_type()) else None
    responses = _make_responses(options.responses, plan, seed, options.participant, clock, window, display)
    announce = None
    if options.responses not in ("sim", "none"):  # a person answers: the experimenter reads the question and prompts
        print(f"psyop run: question for the participant: {plan.response.question}", file=sys.stderr)

        def announce(text: str) -> None:
            print(f"psyop run: prompt: {text}", file=sys.stderr)
    try:
        try:
            gaze.start()
        except (ConnectionError, OSError) as exc:
            raise UserError(f"cannot start tracker {options.tracker}: {exc}", "--tracker") from exc
        sync = getattr(gaze, "sync", None)
        metadata["clock_sync"] = sync.as_dict() if sync is not None else None
        completed = store.open(metadata)
        logged = recover_tables(paths)[0] if completed else None
        if isinstance(clock, VirtualClock) and logged is not None and len(logged):
            clock.sleep_until(float(logged["trial_end_s"].max()))
        # adaptive procedures are rebuilt from the logged trials: no state of their own to lose
        adaptive = AdaptiveLevels.from_log(plan.adaptive, logged) if plan.adaptive is not None else None
        path = plan.fixation
        every_frame = (not (clock.virtual and not responses.needs_images)) if options.every_frame is None \
            else options.every_frame
        renderer, rendering = _make_renderer(options.render, plan, display, options.window_scale,
                                             1.0 if every_frame else options.check_scale,
                                             None if every_frame else options.check_images)
        store.update_metadata(rendering=rendering)
        config = LoopConfig(
            refresh_hz=float(display_profile.refresh_hz),
            every_frame=every_frame,
            pursuit_eccentricity_deg=path.eccentricity_deg if path else 16.0,
            pursuit_speed_deg_s=path.speed_deg_s if path else 90.0,
            phase_delay_s=options.phase_delay_s,
            progress=options.progress,
            hand_last_n=plan.response.average_last_samples,
            min_valid_gaze_share=plan.min_valid_gaze_share,
        )
        loop = TrialLoop(
            identity={"study": study, "participant": options.participant, "session": options.session},
            phases=plan.phases, clock=clock, gaze=gaze, responses=responses,
            renderer=renderer, display=display, store=store, config=config, pose=pose,
            response=plan.response, announce=announce, adaptive=adaptive,
        )
        outcome = loop.run(schedule, completed)
    finally:
        if renderer is not None:
            renderer.close()
        responses.close()
        gaze.close()
        pose.close()
        display.close()
    summary = {"outcome": outcome.status, "message": outcome.message, "latency": outcome.latency,
               "tracker": gaze.stats(), "pose": {"source": options.pose, "hand_samples_held": loop.n_hand_held,
                        "hand_trials_reused": getattr(pose, "n_reused_hand_trials", 0)}}
    display_summary = display.summary()
    if "display_flip_period_s" in display_summary:  # from the flip timestamps (least squares)
        summary["display_flip_period_s"] = display_summary["display_flip_period_s"]
    summary["display"] = display_summary
    if loop.display_interruptions:
        summary["display_interruptions"] = loop.display_interruptions
    store.finalise(status="complete" if outcome.status == "complete" else "incomplete", summary=summary)
    if options.write_description:
        write_dataset_description(options.data_root, simulated=options.simulated)
    return outcome


def print_outcome(outcome: SessionOutcome, stream: Any = sys.stderr) -> None:
    lat = outcome.latency
    print(f"psyop run: {outcome.status}: {outcome.message}", file=stream)
    if lat.get("n_frames"):
        print(f"  gaze sample age at frame submit over {lat['n_frames']} frames: median "
              f"{lat['sample_age_median_ms']:.2f} ms, p99 {lat['sample_age_p99_ms']:.2f} ms, "
              f"max {lat['sample_age_max_ms']:.2f} ms; {lat.get('n_frames_held', 0)} frames held the last valid gaze",
              file=stream)
