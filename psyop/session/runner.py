"""Assemble a session (clock, gaze, responses, renderer, display, store) and run it.

This is what ``psyop run`` and ``psyop simulate`` call. Everything a session used is
recorded in its session.json: protocol text and hash, seed, package versions, eye
model, display, tracker clock-sync, host.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import importlib.metadata
import platform
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pandas as pd
import pyarrow as pa

from psyop.atomic import io_error
from psyop.errors import UserError
from psyop.protocol.model import Protocol
from psyop.session.backends import BackendContext, build, is_real_time
from psyop.session.clock import RealClock, VirtualClock
from psyop.session.frames import CameraRenderer, Display
from psyop.session.gaze.simulated import SimulatedTrackerConfig, seed_for
from psyop.session.log.layout import SessionPaths, session_paths, write_dataset_description
from psyop.session.log.schema import trial_schema
from psyop.adaptive.session import AdaptiveLevels, add_log_columns
from psyop.session.log.store import SessionLog, SessionStore, recover_tables
from psyop.session.loop import LoopConfig, SessionOutcome, TrialLoop, pursuit_fields
from psyop.session.plan import DEFAULT_IPD_M, SessionPlan, compile_plan
from psyop.session.log.raw_gaze import raw_gaze_table
from psyop.session.resume import accept_protocol_change, check_options, resolve_seed

if TYPE_CHECKING:
    from psyop.mesh.load import MeshFiles

__all__ = ["DEFAULT_IPD_M", "SessionOptions", "StoreFactory", "print_outcome", "run_session"]
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
    lsl_markers: bool = False  # publish trial events as an LSL marker stream (psyop.session.lsl_markers)
    lsl_wait_s: float = 10.0  # --lsl-markers: wait this long for a recorder to connect before the first trial
    participant_index: int | None = None  # keys block_order: latin_square (None: the number the ID ends in)
    mesh_files: MeshFiles | None = None  # the models validation read (psyop.mesh.MeshFiles), reused (None: read anew)

    @property
    def simulated_sources(self) -> tuple[str, ...]:
        """Every source of the session that is not a participant's live input, as ``kind:spec``: a
        simulated or replayed gaze stream, the simulated observer, a simulated or replayed head pose."""
        sources = []
        if self.tracker == "sim" or self.tracker.startswith("replay:"):
            sources.append(f"tracker:{self.tracker}")
        if self.responses == "sim":
            sources.append("responses:sim")
        if self.pose == "sim" or self.pose.startswith(("replay:", "replay-by-condition:")):
            sources.append(f"pose:{self.pose}")
        return tuple(sources)

    @property
    def simulated(self) -> bool:
        """Not a person's data: the gaze is simulated or replayed (it drove the rendering, whoever answered:
        ``--tracker sim --responses openxr`` included), or the simulated observer answered. A simulated or
        replayed head pose alone is listed in :attr:`simulated_sources` but does not decide: a desktop
        session has no head tracker to take it from."""
        return any(source.startswith(("tracker:", "responses:")) for source in self.simulated_sources)


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


def _make_renderer(mode: str, plan: SessionPlan, display: Display, window_scale: float, scale: float,
                   max_images: int | None, mesh_files: MeshFiles | None = None) -> tuple[Any, str]:
    """The frame renderer and a description of it for session.json (``mesh_files``: the session's models).

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
                              check_every=WATCHED_CHECK_EVERY, mesh_files=mesh_files),
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
                          check_every=WATCHED_CHECK_EVERY if max_images is None else 1, mesh_files=mesh_files),
            f"images at scale {scale:g}, {limit}")


#: makes the log a session records into from its paths and trial schema (default: the durable
#: :class:`~psyop.session.log.store.SessionStore`; psyop.power passes an in-memory log for throwaway replications)
StoreFactory = Callable[[SessionPaths, pa.Schema], SessionLog]


def run_session(
    protocol: Protocol,
    compile_schedule: Callable[[Protocol, int], pd.DataFrame],
    options: SessionOptions,
    store_factory: StoreFactory | None = None,
) -> SessionOutcome:
    """Run (or resume) one session to the end of its schedule, or to a clean stop.

    The protocol is compiled into a :class:`~psyop.session.plan.SessionPlan` first; everything
    below runs from the plan. ``store_factory``: where the trials are recorded (None: the durable
    session log under ``options.data_root``, with ``options.fsync``)."""
    plan = compile_plan(protocol)
    study = plan.study
    paths = session_paths(options.data_root, study, options.participant, options.session)
    check_options(clock=options.clock, responses=options.responses, tracker=options.tracker, pose=options.pose,
                  display=options.display)
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

    store = (SessionStore(paths, trial_schema(schedule), fsync=options.fsync) if store_factory is None
             else store_factory(paths, trial_schema(schedule)))
    metadata = {
        "study": study, "participant": options.participant, "session": options.session, "seed": seed,
        "simulated": options.simulated, "simulated_sources": list(options.simulated_sources),
        "protocol_sha256": protocol_sha256,
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
    from psyop.mesh.load import MeshFiles
    from psyop.stimulus.meshes import protocol_mesh_records

    source = Path(protocol.source_name).parent if protocol.source_name else None  # as SceneRenderer reads them
    mesh_files = options.mesh_files if options.mesh_files is not None else MeshFiles(source or Path.cwd())
    metadata["meshes"] = protocol_mesh_records(protocol.scene, source, mesh_files)
    renderer: Any = None
    loop: TrialLoop | None = None
    events: list[Any] = []
    if options.lsl_markers:
        if clock.virtual:
            raise UserError("--lsl-markers stamps events on the LSL clock in real time; on --clock virtual they would "
                            "carry times that never happened: use --clock real", "--clock")
        from psyop.session.lsl_markers import LslMarkerOutlet

        markers = LslMarkerOutlet({**metadata, "seed": seed}, clock.now_s)
        events.append(markers)
        recorded = markers.wait_for_recorder(options.lsl_wait_s)
        print(f"psyop run: LSL marker stream 'psyop_markers': "
              + ("a recorder is connected" if recorded else f"no recorder connected within {options.lsl_wait_s:g} s; "
                 "markers sent before one connects are recorded by nobody"), file=sys.stderr)
        metadata["lsl_markers_recorder_at_start"] = recorded
    metadata["lsl_markers"] = options.lsl_markers
    # the display first: responses (a window's keys) and headset trackers are built on it
    context = BackendContext(clock=clock, seed=seed, plan=plan, participant=options.participant,
                             protocol_sha256=protocol.source_sha256, schedule=schedule,
                             tracker_faults=options.tracker_faults, window_scale=options.window_scale,
                             session=options.session, xr_request_exit_at_frame=options.xr_request_exit_at_frame)
    with contextlib.ExitStack() as built:  # a backend that cannot be built closes those built before it
        display = build("display", options.display, context)
        built.callback(display.close)
        context = dataclasses.replace(context, display=display)
        gaze = build("tracker", options.tracker, context)
        built.callback(gaze.close)
        pose = build("pose", options.pose, context)
        built.callback(pose.close)
        responses = build("responses", options.responses, context)
        built.pop_all()
    events += context.event_sinks
    announce = None
    if is_real_time("responses", options.responses):  # a person answers: the experimenter reads the question and prompts
        print(f"psyop run: question for the participant: {plan.response.question}", file=sys.stderr)

        def announce(text: str) -> None:
            print(f"psyop run: prompt: {text}", file=sys.stderr)
    try:
        try:
            gaze.start()
        except (ConnectionError, OSError) as exc:
            raise UserError(f"cannot start tracker {options.tracker}: {exc}", "--tracker") from exc
        sync = gaze.clock_sync()
        metadata["clock_sync"] = sync.as_dict() if sync is not None else None
        metadata["tracker_at_start"] = gaze.stats()  # e.g. the tracker's own calibration result
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
                                             None if every_frame else options.check_images, mesh_files)
        store.update_metadata(rendering=rendering)
        config = LoopConfig(
            refresh_hz=float(display_profile.refresh_hz),
            every_frame=every_frame,
            **pursuit_fields(path),  # the moving target's path (psyop.quality rebuilds the target the same way)
            phase_delay_s=options.phase_delay_s,
            progress=options.progress,
            hand_last_n=plan.response.average_last_samples,
            min_valid_gaze_share=plan.min_valid_gaze_share,
        )
        loop = TrialLoop(
            identity={"study": study, "participant": options.participant, "session": options.session},
            phases=plan.phases, clock=clock, gaze=gaze, responses=responses,
            renderer=renderer, display=display, store=store, config=config, pose=pose,
            response=plan.response, announce=announce, adaptive=adaptive, events=tuple(events),
        )
        outcome = loop.run(schedule, completed)
    finally:
        if renderer is not None:
            renderer.close()
        responses.close()
        gaze.close()
        # raw gaze samples not yet in a trial record (a discarded trial's, or after the last one)
        store.append_gaze(raw_gaze_table(gaze.drain_raw(), run=store.run_index,
                                         trial=loop.current_trial if loop is not None else -1),
                          key=loop.current_trial if loop is not None else -1)
        pose.close()
        for sink in events:
            if sink is not gaze:  # a tracker that takes events is closed as the tracker
                sink.close()
        display.close()
    summary = {"outcome": outcome.status, "message": outcome.message, "latency": outcome.latency,
               "tracker": gaze.stats(), "pose": {"source": options.pose, "hand_samples_held": loop.n_hand_held,
                        "hand_trials_reused": pose.n_reused_hand_trials}}
    display_summary = display.summary()
    if "display_flip_period_s" in display_summary:  # from the flip timestamps (least squares)
        summary["display_flip_period_s"] = display_summary["display_flip_period_s"]
    summary["display"] = display_summary
    if loop.display_interruptions:
        summary["display_interruptions"] = loop.display_interruptions
    store.finalise(status="complete" if outcome.status == "complete" else "incomplete", summary=summary)
    if options.write_description:
        try:
            write_dataset_description(options.data_root, simulated=options.simulated)
        except OSError as exc:
            raise io_error(exc, fix=f"the session itself is finalised ({outcome.message}); free space, then run "
                           f"`psyop recover {options.data_root}` to write the dataset description") from exc
    return outcome


def print_outcome(outcome: SessionOutcome, stream: Any = None) -> None:
    stream = sys.stderr if stream is None else stream  # the stderr of now (not of import time)
    lat = outcome.latency
    print(f"psyop run: {outcome.status}: {outcome.message}", file=stream)
    if lat.get("n_frames"):
        print(f"  gaze sample age at frame submit over {lat['n_frames']} frames: median "
              f"{lat['sample_age_median_ms']:.2f} ms, p99 {lat['sample_age_p99_ms']:.2f} ms, "
              f"max {lat['sample_age_max_ms']:.2f} ms; {lat.get('n_frames_held', 0)} frames held the last valid gaze",
              file=stream)
