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
from typing import TYPE_CHECKING, TextIO

import pandas as pd
import pyarrow as pa

from psyop.session.rows import JsonObject
from psyop.atomic import io_error
from psyop.errors import UserError
from psyop.protocol.model import Protocol
from psyop.run.assembly import Backends, assemble, display_used, open_markers
from psyop.run.backends import BackendContext, is_real_time
from psyop.run.headset import calibrate_before_trials, raise_if_calibration_failed
from psyop.session.clock import Clock, RealClock, VirtualClock
from psyop.session.controls import ESCAPE_KEY, PAUSE_KEY, SessionControls, controls_for
from psyop.session.frames import CameraRenderer, Display, FrameRenderer
from psyop.session.gaze.simulated import SimulatedTrackerConfig, seed_for
from psyop.session.log.record import read_record
from psyop.session.log.layout import SessionPaths, session_paths, write_dataset_description
from psyop.session.log.schema import trial_schema
from psyop.adaptive.session import AdaptiveLevels, add_log_columns
from psyop.session.log.screens_log import ScreenRecorder
from psyop.session.log.store import SessionLog, SessionStore, recover_tables
from psyop.session.validation import gaze_validator
from psyop.session.screens import Pacing, ScreenRunner, session_screens
from psyop.session.scale_picker import RemappableSource
from psyop.protocol.kinds.confidence import SCALE_CONTROLLER
from psyop.session.rows import TrialRow
from psyop.session.gaze.delay import DelayedGaze
from psyop.session.loop import BetweenTrials, LoopConfig, LoopFacts, LoopOptions, SessionOutcome, TrialLoop
from psyop.session.plan import DEFAULT_IPD_M, SessionPlan, compile_plan
from psyop.session.log.raw_gaze import raw_gaze_table
from psyop.run.resume import accept_protocol_change, check_free, check_options, resolve_seed
from psyop.session.timing import with_timing_fields

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
    lsl_markers: bool = False  # publish trial events as an LSL marker stream (psyop.devices.lsl_markers)
    lsl_wait_s: float = 10.0  # --lsl-markers: wait this long for a recorder to connect before the first trial
    participant_index: int | None = None  # keys block_order: latin_square (None: the number the ID ends in)
    mesh_files: MeshFiles | None = None  # the models validation read (psyop.mesh.MeshFiles), reused (None: read anew)
    experimenter_window: bool = False  # a mirror and status window for the experimenter (psyop.devices.experimenter)
    experimenter_window_optional: bool = False  # on by default, not asked for: one that cannot open is a warning
    mirror_eye: str = "left"  # the experimenter window mirrors the left eye, the right one, or both
    mirror_width_px: int = 320  # each mirrored eye's width in the experimenter window (pixels)
    #: read the terminal's keys (answers, Escape, p, c); None: when standard input is a foreground terminal and the
    #: clock is real (psyop.devices.responses.terminal)
    terminal_keys: bool | None = None

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
        ``--tracker sim --responses openxr`` included), or the simulated observer answered, or a simulated or
        replayed head pose stood in for a headset's own (``--display openxr --pose sim``: it placed the head
        the images were rendered for). On a desktop display a simulated head pose alone is listed in
        :attr:`simulated_sources` but does not decide: there is no head tracker to take it from (a reach
        answered from its hand does: :meth:`simulated_for`)."""
        if any(source.startswith(("tracker:", "responses:")) for source in self.simulated_sources):
            return True
        return self.display.startswith("openxr") and any(s.startswith("pose:") for s in self.simulated_sources)

    def simulated_for(self, reach: bool) -> bool:
        """:attr:`simulated`, and a session whose responses are reaches (``reach``) measured on a simulated or
        replayed hand: the distance each trial records is not a person's."""
        return self.simulated or (reach and any(s.startswith("pose:") for s in self.simulated_sources))


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
                   max_images: int | None, mesh_files: MeshFiles | None = None) -> tuple[FrameRenderer, str]:
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
    except Exception as exc:  # any OpenGL/EGL failure: re-raised or reported
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


@dataclass
class _Opened:
    """What :func:`_open` resolved for one run: the plan, paths, seed, schedule, clock, log and metadata."""

    plan: SessionPlan
    paths: SessionPaths
    seed: int
    schedule: pd.DataFrame
    clock: Clock
    store: SessionLog
    metadata: JsonObject = field(default_factory=dict)
    mesh_files: MeshFiles | None = None  # the session's models, read once for session.json and the scene
    #: session.json ``timing_reruns`` of the earlier runs (a resume keeps them and counts max_reruns over them)
    earlier_reruns: list[JsonObject] = field(default_factory=list)


def run_session(
    protocol: Protocol,
    compile_schedule: Callable[[Protocol, int], pd.DataFrame],
    options: SessionOptions,
    store_factory: StoreFactory | None = None,
) -> SessionOutcome:
    """Run (or resume) one session to the end of its schedule, or to a clean stop.

    The protocol is compiled into a :class:`~psyop.session.plan.SessionPlan` first; everything
    below runs from the plan. ``store_factory``: where the trials are recorded (None: the durable
    session log under ``options.data_root``, with ``options.fsync``). Three steps: open (options,
    seed, schedule, clock, log, metadata), run (the backends assembled by :mod:`psyop.run.assembly`,
    closed by it whatever raises) and finalise (the summary, the finalised session.json)."""
    opened = _open(protocol, compile_schedule, options, store_factory)
    markers = open_markers(opened.metadata, opened.clock, options.lsl_wait_s) if options.lsl_markers else None
    opened.metadata["lsl_markers"] = options.lsl_markers
    controls = _controls(opened.plan, options)
    context = BackendContext(clock=opened.clock, seed=opened.seed, plan=opened.plan, participant=options.participant,
                             protocol_sha256=protocol.source_sha256, schedule=opened.schedule,
                             tracker_faults=options.tracker_faults, window_scale=options.window_scale,
                             session=options.session, xr_request_exit_at_frame=options.xr_request_exit_at_frame,
                             controls=controls, mirror_eye=options.mirror_eye, mirror_width_px=options.mirror_width_px)
    specs = {"display": options.display, "tracker": options.tracker, "pose": options.pose,
             "responses": options.responses}
    with assemble(specs, context, markers, experimenter_window=options.experimenter_window,
                  window_optional=options.experimenter_window_optional,
                  terminal=_reads_terminal(options)) as bundle:
        outcome, loop = _run(opened, bundle, options, controls, context.on_recalibrate)
    _finalise(opened, bundle, loop, outcome, options)
    raise_if_calibration_failed(outcome)
    return outcome


def _controls(plan: SessionPlan, options: SessionOptions) -> SessionControls:
    """The session's control keys (psyop.session.controls): with ``--responses keyboard`` the key map's keys stay
    answers, and a control key among them is named on the console (it does not work in this session)."""
    answers = list(plan.response.inputs.keys) if options.responses.partition(":")[0] == "keyboard" else []
    controls = controls_for(answers)
    for key in controls.unavailable():
        _notice(f"the key {key!r} answers in this session (the response key map), so it does not "
                f"{'pause' if key == PAUSE_KEY else 'end' if key == ESCAPE_KEY else 'recalibrate'}")
    return controls


def _reads_terminal(options: SessionOptions) -> bool:
    """Whether the session reads the terminal's keys (``terminal_keys``; by default a live session in a terminal)."""
    if options.terminal_keys is not None:
        return options.terminal_keys
    from psyop.devices.responses.terminal import terminal_usable

    return options.clock == "real" and terminal_usable()


def _open(protocol: Protocol, compile_schedule: Callable[..., pd.DataFrame], options: SessionOptions,
          store_factory: StoreFactory | None) -> _Opened:
    """Resolve the options against any earlier run of the session: plan, seed, schedule, clock, log, metadata."""
    plan = compile_plan(protocol, responses=options.responses)
    paths = session_paths(options.data_root, plan.study, options.participant, options.session)
    check_options(clock=options.clock, responses=options.responses, tracker=options.tracker, pose=options.pose,
                  display=options.display)
    check_free(paths)
    record = read_record(paths)  # session.json of an earlier run, read once here (the store checks it under the lock)
    seed = resolve_seed(paths, record, options.seed, seed_for(plan.study, options.participant, options.session))
    protocol_sha256 = accept_protocol_change(paths, record, protocol) if options.allow_protocol_change \
        else protocol.source_sha256
    from psyop.mesh.load import MeshFiles
    from psyop.schedule.counterbalance import resolve_participant_index

    participant_index = resolve_participant_index(options.participant_index, options.participant,
                                                  record.participant_index if record is not None else None)
    schedule = compile_schedule(protocol, seed, participant_index=participant_index)
    if plan.adaptive is not None:  # the adaptive level and the procedure's state are logged per trial
        schedule = add_log_columns(schedule, plan.adaptive)
    if options.clock == "virtual":
        clock: Clock = VirtualClock()
    elif options.clock == "real":
        clock = RealClock()
    else:
        raise UserError(f"unknown clock {options.clock!r}; use virtual or real", "--clock")
    try:  # the schedule's columns, the log's, then the measured timing of each drawn phase (psyop.session.timing)
        image_observer = plan.observer is not None and plan.observer.kind == "image"  # its decision values logged
        schema = with_timing_fields(trial_schema(schedule, image_observer=image_observer), plan.phases)
    except ValueError as exc:
        raise UserError(str(exc), protocol.source_name or plan.study) from exc
    store = (SessionStore(paths, schema, fsync=options.fsync) if store_factory is None
             else store_factory(paths, schema))
    source = Path(protocol.source_name).parent if protocol.source_name else None  # as SceneRenderer reads them
    mesh_files = options.mesh_files if options.mesh_files is not None else MeshFiles(source or Path.cwd())
    opened = _Opened(plan, paths, seed, schedule, clock, store, mesh_files=mesh_files,
                     earlier_reruns=list(record.timing_reruns) if record is not None else [])
    opened.metadata = _metadata(protocol, opened, options, participant_index, protocol_sha256)
    return opened


def _metadata(protocol: Protocol, opened: _Opened, options: SessionOptions, participant_index: int | None,
              protocol_sha256: str) -> JsonObject:
    """session.json's fields known before the backends are built (in the order they are written)."""
    from psyop.schedule.counterbalance import block_sequence
    from psyop.stimulus.meshes import protocol_mesh_records
    from psyop.session.achieved import display_output
    from psyop.session.log.recorded_design import design_of

    randomisation = protocol.design.randomisation
    source = Path(protocol.source_name).parent if protocol.source_name else None  # as SceneRenderer reads them
    return {
        "study": opened.plan.study, "participant": options.participant, "session": options.session,
        "seed": opened.seed, "simulated": _simulated(options, opened.plan),
        "simulated_sources": list(options.simulated_sources),
        # who answered when no person did: the protocol's observer kind (psychometric_2afc, image, ...); None: a person
        "observer": opened.plan.observer.kind if options.responses == "sim" and opened.plan.observer is not None
        else None,
        "protocol_sha256": protocol_sha256,
        "protocol_file_sha256": protocol.source_sha256,
        "protocol_text": protocol.source_text, "protocol_file": protocol.source_name,
        "n_trials_scheduled": int(len(opened.schedule)), **opened.plan.metadata(), "packages": package_versions(),
        "participant_index": participant_index,
        "block_order": {"kind": randomisation.block_order, "blocks": block_sequence(opened.schedule, randomisation.by)}
        if randomisation.kind == "blocked" else None,
        "python": platform.python_version(), "host": platform.node(),
        "tracker": options.tracker, "responses": options.responses,
        "display_mode": options.display, "clock": options.clock,
        "pose": options.pose, "meshes": protocol_mesh_records(protocol, source, opened.mesh_files),
        # calibrated (the calibration file and the output's method) or pixel values (psyop.protocol.luminance)
        "display_output": display_output(protocol, opened.schedule, opened.plan, source),
        # the command line's fault rates of the simulated tracker (the analysis rebuilds its stream from them)
        "sim_tracker_faults": {"dropout_rate_hz": options.tracker_faults.dropout_rate_hz,
                               "nan_burst_rate_hz": options.tracker_faults.nan_burst_rate_hz}
        if options.tracker.partition(":")[0] == "sim" else None,
        # what the analysis reads of the protocol, typed (SessionRecord.study_design reads it through the same model)
        "study_design": design_of(protocol).model_dump(mode="json"),
    }


def _simulated(options: SessionOptions, plan: SessionPlan) -> bool:
    """session.json's ``simulated`` (:meth:`SessionOptions.simulated_for` the plan's response kind)."""
    return options.simulated_for(plan.kind.needs_hand_pose)


def _announcer(plan: SessionPlan, responses_spec: str) -> Callable[[str], None] | None:
    """Where prompts go when a person answers (the experimenter reads the question and prompts), else None."""
    if not is_real_time("responses", responses_spec):
        return None
    print(f"psyop run: question for the participant: {plan.response.question}", file=sys.stderr)

    def announce(text: str) -> None:
        print(f"psyop run: prompt: {text}", file=sys.stderr)
    return announce


def _notice(text: str) -> None:
    """One line on the experimenter's console (stderr), e.g. a trial the timing rule runs again."""
    print(f"psyop run: {text}", file=sys.stderr, flush=True)


def _run(opened: _Opened, bundle: Backends, options: SessionOptions, controls: SessionControls | None = None,
         on_recalibrate: list[BetweenTrials] | None = None) -> tuple[SessionOutcome, TrialLoop]:
    """Start the tracker, open the log, make the renderer (closed first by ``bundle``) and run the loop."""
    plan, clock, store, gaze = opened.plan, opened.clock, opened.store, bundle.gaze
    if plan.latency.adds:  # display.added_latency_ms: frames take past samples from the raw stream (docs/latency.md)
        gaze = DelayedGaze(gaze)
    announce = _announcer(plan, options.responses)
    current = [-1]  # the trial in progress when the loop stops (for the raw gaze no trial recorded)
    bundle.after_tracker_closed = lambda: store.append_gaze(
        raw_gaze_table(gaze.drain_raw(), run=store.run_index, trial=current[0]), key=current[0])
    try:
        gaze.start()
    except (ConnectionError, OSError) as exc:
        raise UserError(f"cannot start tracker {options.tracker}: {exc}", "--tracker") from exc
    sync = gaze.clock_sync()
    opened.metadata["clock_sync"] = sync.as_dict() if sync is not None else None
    opened.metadata["tracker_at_start"] = gaze.stats()  # e.g. the tracker's own calibration result
    completed = store.open(opened.metadata)
    logged = recover_tables(opened.paths)[0] if completed else None
    if isinstance(clock, VirtualClock) and logged is not None and len(logged):
        clock.sleep_until(float(logged["trial_end_s"].max()))
    # adaptive procedures are rebuilt from the logged trials: no state of their own to lose
    adaptive = AdaptiveLevels.from_log(plan.adaptive, logged) if plan.adaptive is not None else None
    every_frame = (not (clock.virtual and not bundle.responses.needs_images)) if options.every_frame is None \
        else options.every_frame
    renderer, rendering = _make_renderer(options.render, plan, bundle.shown, options.window_scale,
                                         1.0 if every_frame else options.check_scale,
                                         None if every_frame else options.check_images, opened.mesh_files)
    bundle.stack.callback(renderer.close)
    store.update_metadata(rendering=rendering)
    # the plan's facts (the moving target's path among them: psyop.quality rebuilds it) and this run's options
    config = LoopConfig.of(LoopFacts.of_plan(plan), LoopOptions(every_frame=every_frame, phase_delay_s=options.phase_delay_s,
                                                                progress=options.progress))
    recorder = store.screen_recorder() if isinstance(store, SessionStore) else None  # screens, pauses (events.parquet)
    if recorder is not None:
        bundle.stack.callback(recorder.close)
    loop = TrialLoop(
        identity={"study": plan.study, "participant": options.participant, "session": options.session},
        phases=plan.phases, clock=clock, gaze=gaze, responses=bundle.responses,
        renderer=renderer, display=bundle.shown, store=store, config=config, pose=bundle.pose,
        response=plan.response, announce=announce, adaptive=adaptive, events=bundle.events,
        validator=gaze_validator(plan.protocol.gaze_validation, store), notice=_notice,
        screens=_screens(plan, opened, bundle, options, fresh=not completed, recorder=recorder),
        controls=controls, control_log=recorder,
    )
    loop.timing_reruns = list(opened.earlier_reruns)
    loop.on_recalibrate.extend(on_recalibrate or ())  # the backends' (a tracker's calibration), before validation
    loop.latency = plan.latency  # the latency each trial adds and the bound it is judged by (psyop.session.latency)
    if loop.validator is not None:
        bundle.stack.callback(loop.validator.close)
    if loop.screens is not None:
        bundle.stack.callback(loop.screens.close)
    bundle.after_tracker_closed = lambda: store.append_gaze(
        raw_gaze_table(gaze.drain_raw(), run=store.run_index, trial=loop.current_trial), key=loop.current_trial)
    # the tracker's in-headset calibration (pupil:...,calibrate-hmd): before the first trial, and on c (psyop.run.headset)
    stopped = calibrate_before_trials(bundle, plan, loop, opened.schedule, completed)
    if stopped is not None:
        return stopped, loop
    return loop.run(opened.schedule, completed), loop


def _screens(plan: SessionPlan, opened: _Opened, bundle: Backends, options: SessionOptions, *,
             fresh: bool, recorder: ScreenRecorder | None) -> ScreenRunner | None:
    """The protocol's ``session:`` screens for this run (None: it has none): the simulated participant paces and
    answers them with ``--responses sim``, nobody with ``none``, else the live participant's answer inputs end
    them, and a source's raw input (``poll_raw``: keyboard, response box) answers questionnaire items
    (psyop.session.screens)."""
    section = plan.protocol.session
    if section is None:
        return None
    name = options.responses.partition(":")[0]
    pacing: Pacing = "simulated" if name == "sim" else "nobody" if name == "none" else "live"
    responses = bundle.responses

    def live_input(row: TrialRow, now_s: float) -> str | None:
        answer = responses.collect(row, now_s)
        return None if answer is None else answer.response

    raw = getattr(responses, "poll_raw", None) if pacing == "live" else None
    # the controllers pick a questionnaire item's point with the stick (psyop.session.scale_picker)
    scale = responses.with_keymap(SCALE_CONTROLLER) if pacing == "live" and isinstance(responses, RemappableSource) \
        else None
    return session_screens(section, pacing=pacing, seed=int(opened.seed), recorder=recorder, fresh=fresh,
                           live_input=live_input if pacing == "live" else None, raw_input=raw, scale_input=scale)


def _finalise(opened: _Opened, bundle: Backends, loop: TrialLoop, outcome: SessionOutcome,
              options: SessionOptions) -> None:
    """The summary of the run into the finalised session.json; the dataset description beside it."""
    summary: JsonObject = {
        "outcome": outcome.status, "message": outcome.message, "latency": outcome.latency,
        "tracker": bundle.gaze.stats(), "pose": {"source": options.pose, "hand_samples_held": loop.n_hand_held,
                                                 "hand_trials_reused": bundle.pose.n_reused_hand_trials}}
    display_summary = bundle.shown.summary()
    if "display_flip_period_s" in display_summary:  # from the flip timestamps (least squares)
        summary["display_flip_period_s"] = display_summary["display_flip_period_s"]
    summary["display"] = display_summary
    summary["frame_timing"] = {**loop.session_timing.summary(), "clock": options.clock,
                               "scope": "the trials this run recorded (psyop timing: the whole session)"}
    # the recorded trials' gaze-to-photon age, overall and by phase kind (psyop.session.latency)
    summary["gaze_age"] = {**loop.session_timing.gaze.summary(loop.latency),
                           "scope": "the trials this run recorded (psyop timing: the whole session)"}
    if loop.display_interruptions:
        summary["display_interruptions"] = loop.display_interruptions
    timing = opened.plan.protocol.timing
    if timing is not None and timing.on_violation == "rerun":  # attempts this run discarded (session.json timing_reruns)
        summary["timing_reruns"] = loop.reruns_this_run()
    # the display as it really was, per run (a resume may run on another headset): docs/data.md
    opened.store.update_run(display_used=display_used(bundle, opened.plan.display, opened.plan.rig.eyes,
                                                      options.window_scale))
    opened.store.finalise(status="complete" if outcome.status == "complete" else "incomplete", summary=summary)
    if options.write_description:
        try:
            write_dataset_description(options.data_root, simulated=_simulated(options, opened.plan))
        except OSError as exc:
            raise io_error(exc, fix=f"the session itself is finalised ({outcome.message}); free space, then run "
                           f"`psyop recover {options.data_root}` to write the dataset description") from exc


def print_outcome(outcome: SessionOutcome, stream: TextIO | None = None) -> None:
    stream = sys.stderr if stream is None else stream  # the stderr of now (not of import time)
    lat = outcome.latency
    print(f"psyop run: {outcome.status}: {outcome.message}", file=stream)
    if lat.get("n_frames"):
        print(f"  gaze sample age at frame submit over {lat['n_frames']} frames: median "
              f"{lat['sample_age_median_ms']:.2f} ms, p99 {lat['sample_age_p99_ms']:.2f} ms, "
              f"max {lat['sample_age_max_ms']:.2f} ms; {lat.get('n_frames_held', 0)} frames held the last valid gaze",
              file=stream)
