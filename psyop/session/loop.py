"""The trial loop: an explicit state machine per trial, driven by the session clock.

Per trial: RECALIBRATE (central cross; single-point drift correction from the gaze at
its end) -> timed presentation phases (stimulus / blank, per response kind) ->
RESPONSE (poll the response source) -> RECORD (durable append). A trial counts only
once its record is fsynced; anything that stops the loop mid-trial (Ctrl-C, tracker
lost) discards that trial and finalises the log, and the session can be resumed.

Between trials the loop runs what was asked for the boundary (:attr:`TrialLoop.between_trials_requests`), and
the experimenter's keys (psyop.session.controls): ``c`` runs :attr:`TrialLoop.on_recalibrate` and the protocol's
gaze validation, ``p`` pauses until pressed again; both are logged in events.parquet (screens ``recalibrate`` and
``pause``). A pause comes only between trials: the trial in progress when ``p`` is pressed runs to its end.

Two frame regimes:
- every frame (a person is watching, or the observer wants images): one frame per
  refresh period, each logged with its gaze sample time, render start, submit time
  and sample age at submit;
- sampled (virtual clock and an observer that needs no images): the clock jumps from
  phase to phase; only a few frames per session are rendered and checked.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum

import numpy as np
import pandas as pd
import pyarrow as pa

from psyop.session.rows import JsonMapping, JsonObject, TrialRecord, TrialRow, frame_records
from psyop.adaptive.session import AdaptiveLevels
from psyop.session.clock import Clock
from psyop.session.controls import SessionControls
from psyop.session.log.screens_log import ScreenRecorder
from psyop.session.events import EventKind, EventSink, SessionEvent
from psyop.session.frames import Display, DisplayInterrupted, FrameRecorder, FrameRenderer, FrameRequest, latency_summary
from psyop.session.log.schema import VIEW_TANGENTS
from psyop.session.gaze.delay import DelayedGaze
from psyop.session.gaze.filter import GazeConditioner
from psyop.session.gaze.plan import FixationPlan, circling_target
from psyop.session.gaze.sample import GazeSample, GazeSource, TrackerLost
from psyop.session.gaze.simulated import seed_for
from psyop.session.log.raw_gaze import raw_gaze_table
from psyop.session.log.store import SessionLog
from psyop.session.latency import GazeLatency
from psyop.session.signals import interrupts_deferred
from psyop.session.pose import ConditionedPose, PoseConditioner, PoseSource, reach_from_positions
from psyop.session.reach import horizontal_reach_m
from psyop.session.phases import PhaseSpec, mode_for
from psyop.session.timing import SessionTiming, TrialTiming
from psyop.session.validation import GazeValidator, ValidationStopped
from psyop.protocol.timing import TimingSection
from psyop.schedule.rows import interval_values
from psyop.datacontract import typed_response
from psyop.session.plan import TIMEOUT_RESPONSE, FixationPath, FixationPoint, ResponsePlan, SessionPlan
from psyop.session.progress import Progress, session_progress
from psyop.session.responses.base import RawInputSource, Response, ResponseSource, score
from psyop.protocol.kinds.adjustment import AdjustmentSpec, path_column
from psyop.session.screens import ScreenRunner
from psyop.protocol.kinds.confidence import ConfidenceScale
from psyop.session.confidence import ConfidenceAsker
from psyop.session.rating_stick import StickQuestion, ask_on_stick, stick_question
from psyop.session.scale_picker import MappedRawSource, PickerPacing, picks_on_scale


class TimingStopped(Exception):
    """The protocol's ``timing.max_rerun_share`` is spent: the session stops (exit 3, resumable) rather than
    discarding trial after trial; the message names the rule and what to change."""


#: one thing to do at the next trial boundary: called with the loop and the trial about to run (psyop.session.loop
#: TrialLoop.between_trials_requests, TrialLoop.on_recalibrate)
BetweenTrials = Callable[["TrialLoop", int], None]
#: what the display shows while the session is paused (no stimulus, the background)
PAUSE_PHASE = PhaseSpec("pause", 0.0, "blank", "none")


class TrialState(str, Enum):
    RECALIBRATE = "recalibrate"
    PRESENT = "present"
    RESPONSE = "response"
    RECORD = "record"
    DONE = "done"


@dataclass(frozen=True)
class LoopFacts:
    """What the study fixes for the loop: the display's refresh, the fixation targets' geometry and
    the protocol's response and gaze rules (:meth:`of_plan` reads them from the session plan)."""

    refresh_hz: float = 90.0
    pursuit_eccentricity_deg: float = 16.0
    pursuit_speed_deg_s: float = 90.0
    pursuit_centre_deg: tuple[float, float] = (0.0, 0.0)  # Fick angles the target circles (plan.fixation)
    pursuit_id: str = "fixation"  # the fixation target's id: schedule columns <id>_start_deg, <id>_direction
    #: plan.fixation: when given, each trial's pursuit follows its path (factor levels of centre, radius, speed)
    pursuit_path: FixationPath | None = None
    #: plan.fixation_point: the static fixation target 'fixate' phases look at (its centre per trial)
    fixate_point: FixationPoint | None = None
    free_radius_deg: float = 10.0
    fixation_distance_m: float = 1.0
    hand_last_n: int = 10  # reach = mean of the last N hand samples (protocol response.average_last_samples)
    min_valid_gaze_share: float = 0.5  # protocol trial.min_valid_gaze_share: below it gaze_ok is False
    timing: TimingSection | None = None  # protocol timing: the dropped-frame rule of a trial's intervals
    confidence: ConfidenceScale | None = None  # protocol response.confidence: asked after the choice
    #: protocol response, when the controllers' stick picks its answer (a rating, n_afc with n > 2)
    stick: StickQuestion | None = None

    @classmethod
    def of_plan(cls, plan: SessionPlan) -> LoopFacts:
        """The facts of ``plan``: its display's refresh, its moving target, its response, gaze and timing rules."""
        return cls(refresh_hz=float(plan.display.refresh_hz), **pursuit_fields(plan.fixation),
                   fixate_point=plan.fixation_point,
                   hand_last_n=plan.response.average_last_samples, min_valid_gaze_share=plan.min_valid_gaze_share,
                   timing=plan.protocol.timing, confidence=plan.protocol.response.confidence,
                   stick=stick_question(plan.protocol.response))


@dataclass(frozen=True)
class LoopOptions:
    """How this run of the loop goes (not what the study is): which trials render every frame, the
    gaze source's staleness and confidence limits, progress output, the crash tests' phase delay."""

    every_frame: bool = True
    sampled_trials: tuple[int, ...] = (0, 1)
    sample_every_n_trials: int = 50
    stale_after_s: float = 0.1
    confidence_threshold: float = 0.6
    phase_delay_s: float = 0.0  # real sleep per phase; only for crash-safety tests
    progress: bool = True


@dataclass(frozen=True)
class LoopConfig(LoopOptions, LoopFacts):
    """The loop's configuration: the plan's facts (:class:`LoopFacts`) and the run's options
    (:class:`LoopOptions`), each field declared once, in its own part."""

    @classmethod
    def of(cls, facts: LoopFacts, options: LoopOptions) -> LoopConfig:
        """The configuration of ``facts`` and ``options`` together."""
        fields = {f.name: getattr(facts, f.name) for f in dataclasses.fields(LoopFacts)}
        fields.update({f.name: getattr(options, f.name) for f in dataclasses.fields(LoopOptions)})
        return cls(**fields)


def gaze_ok(valid: int, total: int, min_share: float) -> bool | None:
    """Whether a trial's share of frames with valid gaze reached ``min_share`` (None: no frame
    of the trial measured gaze, e.g. an unsampled trial on the virtual clock)."""
    return None if total == 0 else valid / total >= min_share


@dataclass
class SessionOutcome:
    #: complete | interrupted | tracker_lost | device_error | display_lost | validation_failed | timing_stopped
    status: str
    n_recorded: int
    n_scheduled: int
    message: str
    latency: dict[str, float] = field(default_factory=dict)

    @property
    def exit_code(self) -> int:
        return {"complete": 0, "interrupted": 130}.get(self.status, 3)


class TrialLoop:
    """Runs the remaining trials of a schedule into a :class:`SessionStore`."""

    #: the protocol's gaze-latency rules (psyop.session.latency; the runner sets the plan's): the latency each
    #: trial adds (its gaze source then a DelayedGaze) and the bound its trials are judged by
    latency: GazeLatency = GazeLatency()

    def __init__(
        self,
        *,
        identity: JsonMapping,
        phases: tuple[PhaseSpec, ...],
        clock: Clock,
        gaze: GazeSource,
        responses: ResponseSource,
        renderer: FrameRenderer | None,
        display: Display,
        store: SessionLog,
        config: LoopConfig,
        pose: PoseSource | None = None,
        response: ResponsePlan | None = None,
        announce: Callable[[str], None] | None = None,
        adaptive: AdaptiveLevels | None = None,
        events: tuple[EventSink, ...] = (),
        validator: GazeValidator | None = None,
        notice: Callable[[str], None] | None = None,
        screens: ScreenRunner | None = None,
        controls: SessionControls | None = None,
        control_log: ScreenRecorder | None = None,
    ) -> None:
        self.identity = dict(identity)  # study, participant, session
        self.phases = phases
        # the plan's response phase (timeout, display off); None: wait, blank display
        self.response_plan = response
        self.announce = announce  # where a live session shows the response prompt (experimenter console)
        self.adaptive = adaptive  # adaptive levels: chosen before each trial from the logged history
        self.events = events  # outside recorders told of trial starts, phases, responses, ends (events.py)
        self.validator = validator  # the protocol's gaze validations (psyop.session.validation); None: none
        self.notice = notice  # one console line per timing rerun (the experimenter's console); None: silent
        self.screens = screens  # the protocol's session: screens (psyop.session.screens); None: none
        self._init_controls(controls, control_log)
        self._last_block: int | None = None  # the block of the last trial this run ran (None: none yet)
        self.clock, self.gaze, self.responses = clock, gaze, responses
        self.renderer, self.display, self.store, self.config = renderer, display, store, config
        self.conditioner = GazeConditioner(config.confidence_threshold)
        self.pose = pose  # None: no head/hand tracking (logged as the origin, held)
        self.head_conditioner = PoseConditioner()
        self.hand_conditioner = PoseConditioner((math.nan, math.nan, math.nan))
        self.n_hand_held = 0
        self.frame_period_s = 1.0 / config.refresh_hz
        self._ages: list[float] = []  # sample age at submit, frames with fresh valid gaze
        self._n_held = 0
        self._phase_start_s = 0.0
        self._phase_index = -1  # the timed phase in progress (index into ``phases``; -1: the response phase)
        self._pending: FrameRequest | None = None  # a frame begun for a later phase than the one it was asked in
        self.state = TrialState.DONE
        #: trials the display interrupted (discarded; re-run when ``rerun``), as session.json records them
        self.display_interruptions: list[JsonObject] = []
        self.current_trial = -1  # the trial in progress (-1: none); tags the raw gaze samples
        self._timing = TrialTiming()  # the trial in progress's shown frames (psyop.session.timing)
        self.session_timing = SessionTiming(self.frame_period_s)  # this run's recorded trials: summary.frame_timing
        #: attempts discarded by the protocol's timing rule (re-run at the end of their block), as session.json records them
        #: (a resume starts from the earlier runs' list: psyop.run.runner)
        self.timing_reruns: list[JsonObject] = []
        self.n_scheduled = 0  # the schedule's trials (run() sets it): timing.max_rerun_share's base
        self._last_trial = -1  # the trial last given to the log (the message of a Ctrl-C during its write)

    def _init_controls(self, controls: SessionControls | None, control_log: ScreenRecorder | None) -> None:
        self.controls = controls  # the experimenter's keys (psyop.session.controls); None: none
        self.control_log = control_log  # where pauses and recalibrations are logged (events.parquet); None: nowhere
        #: done (in order, once each) at the next trial boundary, before any pause: fn(loop, trial about to run)
        self.between_trials_requests: deque[BetweenTrials] = deque()
        #: run, in order, when ``c`` asks for a recalibration, before the protocol's gaze validation (e.g. a tracker's
        #: own calibration): fn(loop, trial about to run)
        self.on_recalibrate: list[BetweenTrials] = []
        self._said_no_recalibration = False

    # session -------------------------------------------------------------------------
    def run(self, schedule: pd.DataFrame, completed: set[int]) -> SessionOutcome:
        # a trial the timing rule re-runs goes back in the queue, at the end of its block
        queue = [r for r in frame_records(schedule) if int(r["trial"]) not in completed]
        n_total = len(schedule)
        self.n_scheduled = n_total
        recorded = set(completed)
        bar = session_progress(n_total, len(recorded), f"{self.identity['study']} sub-{self.identity['participant']}",
                               enabled=self.config.progress)
        status, message = "complete", f"all {n_total} trials recorded"
        try:
            self._run_queue(queue, schedule, recorded, bar)
            self._validate("end", -1)
            if self.screens is not None and len(schedule):  # the end questionnaires, the end screen
                self.screens.at_end(self, len(recorded), n_total, frame_records(schedule.tail(1))[0])
            if len(recorded) < n_total:
                message = (f"{len(recorded)} of {n_total} trials recorded; the other {n_total - len(recorded)} were "
                           "not run: their conditions met the adaptive stop rule (session.json adaptive_stop)")
        except (KeyboardInterrupt, TrackerLost, ConnectionError, DisplayInterrupted, ValidationStopped,
                TimingStopped) as exc:
            status, message = self._stopped(exc, recorded, n_total)
        finally:
            bar.close()
        n_reruns = self.reruns_this_run()
        if n_reruns:  # the console's end line and session.json's summary count them
            message += (f"; {n_reruns} attempt(s) discarded by the timing rule and run again "
                        "(session.json timing_reruns)")
        latency = latency_summary(np.array(self._ages), self.frame_period_s)
        latency["n_frames_held"] = self._n_held
        return SessionOutcome(status, len(recorded), n_total, message, latency)

    def _run_queue(self, queue: list[TrialRecord], schedule: pd.DataFrame, recorded: set[int], bar: Progress) -> None:
        """Run the queued trials into the log, each recorded one added to ``recorded``."""
        n_total = len(schedule)
        n_stopped = self._record_stops(schedule, recorded, -1)
        while queue:
            planned = row = queue.pop(0)
            bar.set_postfix(trial=int(row["trial"]), block=int(row.get("block", 0)))
            if self.adaptive is not None and self.adaptive.stopped(row):  # met the stop rule: not run, not logged
                bar.update(1)
                continue
            row = self.adaptive.fill(row) if self.adaptive is not None else row
            self.between_trials(row, len(recorded), n_total)
            if self.screens is not None:  # instructions, breaks, questionnaires due before this trial
                self.screens.before_trial(self, row, len(recorded), n_total)
            self._validate_before(row)
            self.current_trial = int(row["trial"])
            record, frames = self._run_trial_on_display(row)
            if self._rerun_for_timing(planned, record, queue):
                continue
            if self.adaptive is not None:
                record = self.adaptive.complete(record)
            self.state = TrialState.RECORD
            self._last_trial = int(record["trial"])
            with interrupts_deferred():  # Ctrl-C (or SIGTERM) never tears a record half-written
                self._store_trial(record, frames)
                recorded.add(int(record["trial"]))  # counted before a held Ctrl-C is raised
            n_stopped = self._recorded(record, schedule, recorded, n_stopped)
            bar.update(1)
            if self.screens is not None:  # feedback on the trial just recorded (session: feedback)
                self.screens.after_trial(self, record, len(recorded), n_total)

    def _stopped(self, exc: BaseException, recorded: set[int], n_total: int) -> tuple[str, str]:
        """The outcome's status and message when ``exc`` stopped the session."""
        counted = f"{len(recorded)}/{n_total} recorded"
        discarded = f"the trial in progress was discarded, {counted}"
        if isinstance(exc, KeyboardInterrupt):  # Ctrl-C, a stop signal, or Escape in the window (its own words)
            why = f"{exc}: " if str(exc) else ""
            if not why and self.controls is not None and self.controls.stop_reason:  # Escape in the terminal
                why = f"{self.controls.stop_reason}: "
            if self.state is TrialState.RECORD and self._last_trial in recorded:
                return "interrupted", f"{why}interrupted just after trial {self._last_trial} was recorded, {counted}"
            return "interrupted", (f"{why}interrupted during trial (state {self.state.value}); that trial was "
                                   f"discarded, {counted}")
        if isinstance(exc, TrackerLost):
            return "tracker_lost", f"{exc}; {discarded}"
        if isinstance(exc, ConnectionError):
            return "device_error", f"{exc}; {discarded}"
        if isinstance(exc, DisplayInterrupted):
            return "display_lost", f"{exc.reason}; {discarded}"
        if isinstance(exc, TimingStopped):
            return "timing_stopped", f"{exc}; {discarded}"
        return "validation_failed", f"{exc}; {counted}"

    def between_trials(self, row: TrialRow, done: int, n_total: int) -> None:
        """The trial boundary before ``row``: every request queued for it, then a recalibration (``c``) and a
        pause (``p``) when the keys asked for them (module docstring)."""
        trial = int(row["trial"])
        while self.between_trials_requests:
            self.between_trials_requests.popleft()(self, trial)
        if self.controls is None:
            return
        source = self.controls.take_recalibrate()
        if source is not None:
            self._recalibrate(row, source, done, n_total)
        if self.controls.pause_wanted:
            self._pause(row, done, n_total)

    def _recalibrate(self, row: TrialRow, source: str, done: int, n_total: int) -> None:
        """``c`` was pressed: the recalibration hooks, then the protocol's gaze validation (when ``recalibrate``),
        logged; without either, one line (console and events.parquet) the first time."""
        trial, start_s = int(row["trial"]), self.clock.now_s()
        if not self.on_recalibrate and self.validator is None:
            if not self._said_no_recalibration:
                text = ("c (recalibrate) does nothing in this session: the protocol has no gaze_validation: and no "
                        "tracker calibration is hooked in")
                self._say(text)
                self._log_control("recalibrate", row, start_s, start_s, 0.0, source, text, done, n_total)
                self._said_no_recalibration = True
            return
        self._say(f"recalibrating before trial {trial} (c pressed in {source})")
        for hook in list(self.on_recalibrate):
            hook(self, trial)
        text = "recalibration hooks run"
        if self.validator is not None:
            rows = self.validator.run("recalibrate", self, trial)
            text = f"gaze validation run (when recalibrate; mean error {float(rows['mean_error_deg'].iloc[-1]):.2f} deg)"
        end_s = self.clock.now_s()
        self._log_control("recalibrate", row, start_s, end_s, end_s - start_s, source, text, done, n_total)

    def _pause(self, row: TrialRow, done: int, n_total: int) -> None:
        """Wait until ``p`` is pressed again (Escape ends the session meanwhile). A live display keeps getting frames
        (the background, no stimulus); headless, on a virtual clock or without frames the keys are pumped on the wall
        clock (a virtual session clock does not move). Logged with its wall-clock duration."""
        assert self.controls is not None
        controls, trial = self.controls, int(row["trial"])
        self._say(f"paused before trial {trial} (p pressed in {controls.pause_source}); p resumes, Escape ends "
                  "the session")
        start_s, started = self.clock.now_s(), time.monotonic()
        t = start_s
        pause_row = {"trial": -1, "condition": "pause"}
        while controls.pause_wanted:
            if self.clock.virtual or not self.config.every_frame or self.display.name == "headless":
                controls.pump()
                time.sleep(0.02)
                continue
            request = self.display.begin_frame(t)
            if self.renderer is not None and request.should_render:
                self.renderer.render(pause_row, PAUSE_PHASE, "conventional", 0.0, (0.0, 0.0, -1.0), frame=request)
            self.display.end_frame(request, self.renderer.eye_textures() if self.renderer is not None else [])
            t = max(t + self.frame_period_s, request.display_time_s + request.period_s)
        waited_s = time.monotonic() - started
        self._say(f"resumed after {waited_s:.1f} s (p pressed in {controls.pause_source})")
        self._log_control("pause", row, start_s, self.clock.now_s(), waited_s, controls.pause_source,
                          f"paused before trial {trial}", done, n_total)

    def _say(self, text: str) -> None:
        if self.notice is not None:
            self.notice(text)

    def _log_control(self, screen: str, row: TrialRow, start_s: float, end_s: float, duration_s: float,
                     source: str, text: str, done: int, n_total: int) -> None:
        """One events.parquet row of a pause or a recalibration (psyop.session.log.screens_log.EVENTS_SCHEMA);
        ``duration_s``: wall-clock seconds for a pause (a virtual clock stands still)."""
        if self.control_log is None:
            return
        self.control_log.append_event({
            "run": self.store.run_index, "screen": screen, "name": screen, "page": 0, "n_pages": 1,
            "when": "between_trials", "before_trial": int(row["trial"]), "block": int(row.get("block", 0)),
            "after_trial": -1, "trials_done": done, "trials_left": n_total - done, "start_s": start_s,
            "end_s": end_s, "duration_s": duration_s, "ended_by": f"key in {source}", "text": text})

    def _validate_before(self, row: TrialRow) -> None:
        """The protocol's validation before this trial: at the run's first trial (``start``) or when the
        block changes (``between_blocks``); raises ValidationStopped when its requirement is not met."""
        block = int(row.get("block", 0))
        previous, self._last_block = self._last_block, block
        if previous is None:
            self._validate("start", int(row["trial"]))
        elif block != previous:
            self._validate("between_blocks", int(row["trial"]))

    def _validate(self, when: str, before_trial: int) -> None:
        if self.validator is not None and self.validator.runs_at(when):
            self.validator.run(when, self, before_trial)

    def _recorded(self, record: TrialRecord, schedule: pd.DataFrame, recorded: set[int], n_stopped: int) -> int:
        """After a trial is durable: its ``trial_end`` event, the adaptive procedure told (and any condition it
        stopped recorded); the number of stopped conditions."""
        self.current_trial = -1
        self._emit("trial_end", record, float(record["trial_end_s"]),
                   duration_s=float(record["trial_end_s"]) - float(record["trial_start_s"]))
        if self.adaptive is not None:
            self.adaptive.commit(record)
            if self.adaptive.state(str(record["condition"])).finished:
                n_stopped = self._record_stops(schedule, recorded, n_stopped)
        self.state = TrialState.DONE
        return n_stopped

    def _store_trial(self, record: TrialRecord, frames: FrameRecorder) -> None:
        """Append one trial to the log: its row, frames and raw gaze (a log of rows only: the row)."""
        self.session_timing.add(self._timing, self.phases)
        self.session_timing.gaze.add(self._timing.gaze, self.phases, int(record["trial"]), record.get("gaze_age_ok"))
        if self.store.keeps_samples:
            self.store.append_trial(record, frames.table() if len(frames) else None,
                                    self.raw_gaze(int(record["trial"])))
        else:  # a log of trial rows only (psyop.power's in-memory log): no frame or gaze tables built
            self.gaze.drain_raw()
            self.store.append_trial(record, None, None)

    def _run_trial_on_display(self, row: TrialRecord) -> tuple[TrialRecord, FrameRecorder]:
        """Run a trial once the display can show it. A trial the display interrupts (a headset
        session that lost focus) is discarded like a crashed one, the reason recorded in
        session.json (``display_interruptions``), and run again once the display is ready; an
        interruption that ends the display (the runtime stopping) ends the session."""
        while True:
            try:
                self.display.wait_until_ready()
                return self.run_trial(row)
            except DisplayInterrupted as exc:
                self.note_display_interruption(int(row["trial"]), exc)
                if not exc.rerun:
                    raise

    def note_display_interruption(self, trial: int, exc: DisplayInterrupted) -> None:
        """Record in session.json (``display_interruptions``) that the display interrupted ``trial``
        (-1: a gaze validation)."""
        self.display_interruptions.append({"trial": trial, "reason": exc.reason, "at_s": self.clock.now_s(),
                                           "rerun": exc.rerun})
        self.store.update_metadata(display_interruptions=list(self.display_interruptions))

    def _rerun_for_timing(self, planned: TrialRow, record: TrialRecord, queue: list[TrialRecord]) -> bool:
        """Whether the protocol's ``timing: {on_violation: rerun}`` discards this attempt: its intervals dropped
        more frames than allowed and the trial has reruns left. Then the attempt is recorded in session.json
        (``timing_reruns``: trial, dropped frames, why), announced (a ``timing_rerun`` event and one console
        line), its raw gaze kept (gaze.parquet, like any discarded trial's) and the trial queued again at the end
        of its block. A rerun beyond ``timing.max_rerun_share`` of the schedule (this run) raises TimingStopped."""
        rule, trial = self.config.timing, int(record["trial"])
        if rule is None or rule.on_violation != "rerun" or record.get("timing_ok") is not False:
            return False
        n_before = sum(r["trial"] == trial for r in self.timing_reruns)
        if n_before >= rule.max_reruns:
            return False  # kept, flagged (timing_ok false)
        dropped = self._timing.stimulus_dropped(self.phases)
        reason = rule.describe(dropped)
        self._stop_for_reruns(rule, trial, dropped, reason)
        self.timing_reruns.append({"trial": trial, "dropped_frames": dropped, "reason": reason,
                                   "at_s": self.clock.now_s(), "run": self.store.run_index})
        self.store.update_metadata(timing_reruns=list(self.timing_reruns))
        self._emit("timing_rerun", record, self.clock.now_s(), reason)
        if self.notice is not None:
            self.notice(f"trial {trial} discarded, to be run again at the end of its block (rerun {n_before + 1} "
                        f"of at most {rule.max_reruns}): {reason}")
        if self.store.keeps_samples:
            self.store.append_gaze(self.raw_gaze(trial), key=trial)
        block = planned.get("block", 0)
        at = max((i + 1 for i, r in enumerate(queue) if r.get("block", 0) == block), default=0)
        queue.insert(at, dict(planned))
        return True

    def reruns_this_run(self) -> int:
        """Attempts this run discarded for the timing rule (session.json ``timing_reruns`` of this run)."""
        return sum(r.get("run") == self.store.run_index for r in self.timing_reruns)

    def _stop_for_reruns(self, rule: TimingSection, trial: int, dropped: int, reason: str) -> None:
        """Raise TimingStopped when one more rerun would exceed ``timing.max_rerun_share`` of the schedule
        (this run's reruns); the attempt is then discarded like an interrupted trial (a resume runs it) and
        recorded in session.json ``timing_stop``."""
        limit = rule.rerun_limit(self.n_scheduled)
        if limit is None or self.reruns_this_run() + 1 <= limit:
            return
        self.store.update_metadata(timing_stop={"trial": trial, "dropped_frames": dropped, "reason": reason,
                                                "at_s": self.clock.now_s(), "run": self.store.run_index,
                                                "reruns": self.reruns_this_run(), "limit": limit})
        raise TimingStopped(rule.stop_message(limit, self.n_scheduled, reason))

    def _record_stops(self, schedule: pd.DataFrame, recorded: set[int], n_stopped: int) -> int:
        """Write session.json's ``adaptive_stop`` whenever another condition has stopped (so the
        completeness check of `psyop recover` counts its trials as not to be run); the number of
        stopped conditions."""
        if self.adaptive is None:
            return 0
        summary = self.adaptive.stop_summary(schedule, recorded)
        if len(summary["conditions"]) != n_stopped:
            self.store.update_metadata(adaptive_stop=summary)
        return len(summary["conditions"])

    # trial ---------------------------------------------------------------------------
    def run_trial(self, row: TrialRecord) -> tuple[TrialRecord, FrameRecorder]:
        frames = FrameRecorder()
        trial = int(row["trial"])
        sampled = (trial in self.config.sampled_trials) or (trial % max(1, self.config.sample_every_n_trials) == 0)
        start_s = self.clock.now_s()
        self._emit("trial_start", row, start_s)
        self._timing, self._pending = TrialTiming(start_s=start_s), None
        valid, total, drift_deg = self._present(row, frames, start_s, sampled)
        self.state = TrialState.RESPONSE
        response = self._await_confidence(row, frames, self._await_response(row, frames))
        end = self.clock.now_s()
        response, hand_columns = self._track_reach(row, response, end)
        self._emit("response", row, end, response.response)
        record = dict(row)
        record.update(self.identity)
        record.update(
            response=response.response, correct=response.correct, reach_m=response.reach_m,
            chosen_mode=response.chosen_mode, trial_start_s=start_s, trial_end_s=end,
            response_time_s=response.response_time_s, drift_correction_deg=drift_deg,
            gaze_valid_fraction=(valid / total) if total else None, n_frames=len(frames),
            gaze_ok=gaze_ok(valid, total, self.config.min_valid_gaze_share),
            run=self.store.run_index,
        )
        # measured timing (psyop.session.timing); the sampled regime shows no phase whole
        record.update(self._timing.columns(self.phases, self.config.timing, measured=self.config.every_frame))
        record.update(self._timing.gaze.columns(self.phases, self.latency))  # psyop.session.latency
        record.update(dict(response.extras))
        record.update(typed_response(response.response))  # response_value (a number where it is one), outcome
        record.update(hand_columns)
        return record, frames

    def _present(self, row: TrialRow, frames: FrameRecorder, start_s: float, sampled: bool) -> tuple[int, int, float]:
        """The timed phases of a trial from ``start_s``: (frames with valid gaze, frames, drift correction).

        Each phase begins at the nominal end of the one before (on a real clock too: a late frame never
        pushes the phases after it) and lasts its duration; a frame the display will show after the phase's
        end is the next phase's first (``_pending``)."""
        drift_deg = math.nan
        valid = total = 0
        phase_start = start_s
        for index, phase in enumerate(self.phases):
            self.state = TrialState.RECALIBRATE if phase.gaze == "cross" else TrialState.PRESENT
            self._phase_start_s, self._phase_index = phase_start, index
            self._emit("phase", row, phase_start, phase.name)
            self._set_plan(phase, row, phase_start)
            if self.config.phase_delay_s > 0:
                time.sleep(self.config.phase_delay_s)
            end_s = phase_start + phase.duration_s
            paced = phase.ends_after_s is not None and isinstance(self.responses, RawInputSource)
            if paced:  # a live participant ends it: the minimum first (psyop.session.phases.PhaseSpec.ends_after_s)
                end_s = phase_start + float(phase.ends_after_s or 0.0)
            if self.config.every_frame:
                v, n = self._frames_until(end_s, row, phase, frames)
            else:
                v, n = self._sampled_frame(phase_start + 0.5 * phase.duration_s, row, phase, frames) if sampled and phase.renders else (0, 0)
                self.clock.sleep_until(end_s)
            valid, total = valid + v, total + n
            if paced:
                v, n, end_s = self._until_participant_ends(end_s, row, phase, frames)
                valid, total = valid + v, total + n
            if self.state is TrialState.RECALIBRATE:
                sample = self._fresh(self.gaze.latest(self.clock.now_s()))
                drift_deg = self.conditioner.recalibrate(sample, np.array([0.0, 0.0, -1.0]))
            phase_start = end_s
        self._phase_index = -1  # the response phase
        return valid, total, drift_deg

    def _until_participant_ends(self, min_end_s: float, row: TrialRow, phase: PhaseSpec,
                                frames: FrameRecorder) -> tuple[int, int, float]:
        """A participant-paced interval after its minimum (``min_end_s``): frames on until the live source reports
        an input its kind maps (an answer key or button) made at or after the minimum, which ends the interval
        (the response phase follows); (frames with valid gaze, frames, the interval's end)."""
        source = self.responses
        assert isinstance(source, RawInputSource)
        valid = total = 0
        t = min_end_s
        while True:
            now_s = self.clock.now_s()
            if source.raw_inputs(min_end_s - 1e-9, now_s):  # inputs before the minimum are dropped
                return valid, total, max(now_s, min_end_s)
            if self.config.every_frame:  # the display paces the frames (a frame begun during the minimum first)
                if self._pending is not None:
                    request, self._pending = self._pending, None
                else:
                    request = self.display.begin_frame(t)
                v, n = self._frame(row, phase, frames, request)
                valid, total = valid + v, total + n
                t = max(t + self.frame_period_s, request.display_time_s + request.period_s)
            else:
                t = now_s + 0.01
                self.clock.sleep_until(t)

    def _track_reach(self, row: TrialRow, response: Response, end_s: float) -> tuple[Response, TrialRecord]:
        """A reach: take the pose source's last N hand samples (hold last valid), recompute
        the reach from their mean along the horizontal eye-to-target direction and log them
        with the trial (``hand_sample_*`` columns)."""
        if response.reach_m is None or self.pose is None:
            return response, {}
        extras = dict(response.extras)
        endpoint = tuple(float(extras[k]) for k in ("hand_x_m", "hand_y_m", "hand_z_m")) if "hand_x_m" in extras else None
        samples = self.pose.hand(row, end_s, self.config.hand_last_n, endpoint)
        if not samples:
            return response, {}
        hands = [self.hand_conditioner.condition(s) for s in samples]
        self.n_hand_held += sum(h.held for h in hands)
        _, mean = reach_from_positions(np.array([h.position_m for h in hands]), self.config.hand_last_n)
        reach = horizontal_reach_m(mean)  # along the horizontal eye-to-target direction (psyop/session/reach.py)
        extras.update(hand_x_m=float(mean[0]), hand_y_m=float(mean[1]), hand_z_m=float(mean[2]))
        columns = dict(hand_sample_t_s=[h.sample_t_s for h in hands],
                       **{f"hand_sample_{a}_m": [h.position_m[i] for h in hands] for i, a in enumerate("xyz")},
                       hand_sample_valid=[h.valid for h in hands], hand_sample_held=[h.held for h in hands])
        return dataclasses.replace(response, response=f"{reach:.6f}", reach_m=reach, extras=tuple(extras.items())), columns

    def _emit(self, kind: EventKind, row: TrialRow, t_s: float, value: str = "",
              duration_s: float = 0.0) -> None:
        if self.events:
            event = SessionEvent(kind, int(row["trial"]), str(row.get("condition", "")), t_s, value, duration_s)
            for sink in self.events:
                sink.emit(event)

    def raw_gaze(self, trial: int) -> pa.Table:
        """The samples the gaze source delivered since the last call (the raw gaze stream),
        tagged with this run and ``trial``."""
        return raw_gaze_table(self.gaze.drain_raw(), run=self.store.run_index, trial=trial)

    def _set_plan(self, phase: PhaseSpec, row: TrialRow, start_s: float) -> None:
        """Tell the gaze source where the observer is asked to look (a real tracker ignores it)."""
        self.gaze.set_plan(fixation_plan(self.config, phase, row, start_s))

    def _fresh(self, sample: GazeSample | None, added_s: float = 0.0) -> GazeSample | None:
        """A sample older than ``stale_after_s`` (tracker dropout) counts as invalid; a sample delayed on purpose
        by ``added_s`` is judged by its age beyond that."""
        if sample is not None and self.clock.now_s() - sample.timestamp_s - added_s > self.config.stale_after_s:
            return GazeSample(sample.timestamp_s, sample.fixation_m, sample.confidence, False)
        return sample

    def _frame(self, row: TrialRow, phase: PhaseSpec, frames: FrameRecorder, request: FrameRequest) -> tuple[int, int]:
        """The software path of one frame the display asked for: gaze in -> condition -> render
        (for the request's display time, views and targets) -> end the frame -> log."""
        sample, newest_t_s, added_s = self._gaze_for(row)
        gaze = self.conditioner.condition(sample)
        head = self.head_conditioner.condition(self.pose.head(self.clock.now_s()) if self.pose is not None else None)
        render_start = self.clock.now_s()
        check = None
        if self.renderer is not None and phase.renders and request.should_render:
            check = self.renderer.render(row, phase, mode_for(phase, row), request.display_time_s - self._phase_start_s,
                                         gaze.fixation_m, head_pose=(head.position_m, head.orientation_wxyz),
                                         frame=request)
        images = self.renderer.eye_textures() if self.renderer is not None else []
        submit = self.display.end_frame(request, images)
        self._timing.add(self._phase_index, request.display_time_s, request.period_s, request.missed_frames)
        age = submit - gaze.sample_t_s if math.isfinite(gaze.sample_t_s) else math.nan
        if gaze.valid and math.isfinite(age):
            self._ages.append(age)
        else:
            self._n_held += 1
        at_display = request.display_time_s - gaze.sample_t_s if math.isfinite(gaze.sample_t_s) else math.nan
        intrinsic = request.display_time_s - newest_t_s if math.isfinite(newest_t_s) else math.nan
        self._timing.gaze.add(self._phase_index, at_display, intrinsic, gaze.valid, added_s)
        fx, fy, fz = gaze.fixation_m
        frames.add(trial=int(row["trial"]), phase=phase.name, frame=len(frames), gaze_sample_t_s=gaze.sample_t_s,
                   fixation_x_m=fx, fixation_y_m=fy, fixation_z_m=fz, gaze_confidence=gaze.confidence,
                   gaze_valid=gaze.valid, gaze_held=gaze.held, render_start_s=render_start, submit_s=submit,
                   sample_age_s=age, image_checked=check.checked if check else False,
                   image_ok=check.ok if check else None, **_pose_columns("head", head),
                   display_time_s=request.display_time_s, display_period_s=request.period_s,
                   display_should_render=request.should_render, display_missed_frames=request.missed_frames,
                   gaze_age_at_display_s=at_display, added_latency_s=added_s, gaze_age_intrinsic_s=intrinsic,
                   **_view_columns(request))
        if check is not None and check.checked and not check.ok:
            raise RuntimeError(f"trial {row['trial']}: rendered frame failed its check (non-finite or empty)")
        return int(gaze.valid), 1

    def _gaze_for(self, row: TrialRow) -> tuple[GazeSample | None, float, float]:
        """The sample a frame of trial ``row`` is rendered with, the newest sample's time (NaN: none yet) and the
        latency added (s): the newest sample (stale ones invalid), or with ``display.added_latency_ms`` the one
        at or before the newest sample's time minus it, held (psyop.session.gaze.delay; docs/latency.md)."""
        newest = self.gaze.latest(self.clock.now_s())
        newest_t_s = newest.timestamp_s if newest is not None else math.nan
        added_s = self.latency.added_s(row) if self.latency.adds else 0.0
        if added_s <= 0.0:
            return self._fresh(newest), newest_t_s, 0.0
        if not isinstance(self.gaze, DelayedGaze):
            raise RuntimeError("display.added_latency_ms needs the gaze source wrapped in a DelayedGaze "
                               "(psyop.run.runner does it)")
        delayed = self.gaze.before(newest_t_s - added_s) if newest is not None else None
        return self._fresh(delayed, added_s), newest_t_s, added_s

    def _frames_until(self, end_s: float, row: TrialRow, phase: PhaseSpec, frames: FrameRecorder) -> tuple[int, int]:
        """Frames until the phase ends: the display paces them (begin_frame) and says when each is
        shown; a frame is drawn while the next one would still be shown before ``end_s``. The display
        returns the frame due when it is asked (a late frame is drawn for the display's current time, the
        periods it skipped counted: FrameRequest.missed_frames), so the stimulus follows the display clock;
        a frame it will show at or after ``end_s`` is kept for the next phase (``_pending``)."""
        valid = total = 0
        t = self._phase_start_s
        while True:
            if self._pending is not None:
                request, self._pending = self._pending, None
            elif t < end_s - 1e-9:
                request = self.display.begin_frame(t)
            else:
                break
            if request.display_time_s >= end_s - 1e-9:  # shown after this phase: the next one's first frame
                self._pending = request
                return valid, total
            v, n = self._frame(row, phase, frames, request)
            valid, total = valid + v, total + n
            t = min(max(t + self.frame_period_s, request.display_time_s + request.period_s), end_s)
        self.clock.sleep_until(end_s)
        return valid, total

    def _sampled_frame(self, at_s: float, row: TrialRow, phase: PhaseSpec, frames: FrameRecorder) -> tuple[int, int]:
        return self._frame(row, phase, frames, self.display.begin_frame(at_s))

    def _await_response(self, row: TrialRow, frames: FrameRecorder) -> Response:
        plan = self.response_plan
        prompt = plan.phase if plan is not None else PhaseSpec("response", 0.0, "blank", "none")
        timeout_s = plan.timeout_s if plan is not None else None
        if plan is not None and plan.prompt and self.announce is not None:
            self.announce(plan.prompt)
        start_s = self.clock.now_s()
        self._emit("phase", row, start_s, prompt.name)
        slot_s = start_s  # real clock: the display slot the next response frame is asked for
        if self._pending is not None:  # begun during the last timed phase, due in this one
            request, self._pending = self._pending, None
            self._frame(row, prompt, frames, request)
            slot_s = request.display_time_s + request.period_s
        adjustment = plan.adjustment if plan is not None else None
        if adjustment is not None and isinstance(self.responses, RawInputSource):  # a person adjusts, frame by frame
            return self._await_adjustment(row, frames, prompt, adjustment, start_s, slot_s, timeout_s)
        if self.config.stick is not None and picks_on_scale(self.responses):  # the stick picks the answer
            return self._await_rating_stick(row, frames, prompt, start_s, timeout_s)
        while True:
            response = self.responses.collect(row, self.clock.now_s())
            if response is not None:
                return response
            if timeout_s is not None and self.clock.now_s() - start_s >= timeout_s - 1e-9:
                self.responses.timed_out()
                return Response(TIMEOUT_RESPONSE, correct=None, response_time_s=math.nan)
            if self.config.every_frame:
                # virtual clock: one frame per period from now (as ever); real clock: the next display slot (a
                # late frame is drawn for the display's current time, like a timed phase's)
                request = self.display.begin_frame(self.clock.now_s() if self.clock.virtual else slot_s)
                self._frame(row, prompt, frames, request)
                slot_s = request.display_time_s + request.period_s
                wake_s = self.clock.now_s() + self.frame_period_s if self.clock.virtual else slot_s
                if self.display.paced:  # the next begin_frame waits for the display itself
                    continue
            else:
                wake_s = self.clock.now_s() + 0.01
            self.clock.sleep_until(wake_s if timeout_s is None else min(wake_s, start_s + timeout_s))

    def _await_confidence(self, row: TrialRow, frames: FrameRecorder, response: Response) -> Response:
        """The confidence rating after the choice, when the protocol asks one (psyop.session.confidence): its scale
        on the text panel each frame until the source gives a point or the response's timeout passes."""
        if self.config.confidence is None:
            return response
        plan = self.response_plan
        asker = ConfidenceAsker(self.config.confidence, self.responses, self.clock, self.display,
                                timeout_s=plan.timeout_s if plan is not None else None,
                                every_frame=self.config.every_frame, frame_period_s=self.frame_period_s)
        self._emit("phase", row, self.clock.now_s(), asker.phase.name)
        return asker.ask(row, response, lambda request: self._frame(row, asker.phase, frames, request))

    def _await_rating_stick(self, row: TrialRow, frames: FrameRecorder, prompt: PhaseSpec, start_s: float,
                            timeout_s: float | None) -> Response:
        """A rating or an n_afc answered with the controllers' stick (psyop.session.rating_stick), drawn on the
        loop's frame path."""
        assert self.config.stick is not None and self.response_plan is not None
        assert isinstance(self.responses, MappedRawSource)
        pacing = PickerPacing(self.clock, self.display, timeout_s, self.config.every_frame, self.frame_period_s)
        response = ask_on_stick(row, self.response_plan, self.config.stick, self.responses, pacing, start_s,
                                lambda request, phase: self._frame(row, phase, frames, request), prompt.name)
        if response.response == TIMEOUT_RESPONSE:
            self.responses.timed_out()
        return response

    def _await_adjustment(self, row: TrialRow, frames: FrameRecorder, prompt: PhaseSpec, adjustment: AdjustmentSpec,
                          start_s: float, slot_s: float, timeout_s: float | None) -> Response:
        """An adjustment's response phase (psyop.protocol.kinds.adjustment): each frame, the source's raw inputs
        since the phase began move the value (:class:`AdjustmentState`), and the stimulus is drawn with the value
        it has at the frame's display time, written into the row, until the participant confirms (or the phase
        times out). The answer is the final value; its path goes to ``<variable>_path``."""
        source = self.responses
        assert isinstance(source, RawInputSource)
        state = adjustment.state(float(row[adjustment.variable]), start_s)
        column = path_column(adjustment.variable)
        while True:
            now_s = self.clock.now_s()
            for event in source.raw_inputs(start_s, now_s):
                state.apply(event.name, event.t_s, event.amount)
            if state.confirmed_s is not None:
                assert self.response_plan is not None  # an adjustment is the plan's response
                scored = score(self.response_plan.kind, row, state.answer())
                return dataclasses.replace(scored, response_time_s=state.confirmed_s - start_s,
                                           extras=((column, state.path_json()),))
            if timeout_s is not None and now_s - start_s >= timeout_s - 1e-9:
                self.responses.timed_out()
                return Response(TIMEOUT_RESPONSE, correct=None, response_time_s=math.nan,
                                extras=((column, state.path_json()),))
            if self.config.every_frame:  # the display's pacing, as in _await_response
                request = self.display.begin_frame(now_s if self.clock.virtual else slot_s)
                self._frame({**row, adjustment.variable: state.value_at(request.display_time_s)}, prompt, frames,
                            request)
                slot_s = request.display_time_s + request.period_s
                wake_s = self.clock.now_s() + self.frame_period_s if self.clock.virtual else slot_s
                if self.display.paced:
                    continue
            else:
                wake_s = now_s + 0.01
            self.clock.sleep_until(wake_s if timeout_s is None else min(wake_s, start_s + timeout_s))


def _view_columns(request: FrameRequest) -> JsonObject:
    """Frame-log columns of the views the display reported (psyop.session.log.schema.view_fields)."""
    columns: TrialRecord = {}
    for view in request.views:
        e = view.eye
        columns.update({f"view_{e}_{a}_m": float(x) for a, x in zip("xyz", view.centre_m)})
        columns.update({f"view_{e}_q{c}": float(q) for c, q in zip("wxyz", view.orientation_wxyz)})
        columns.update({f"view_{e}_tan_{side}": float(t) for side, t in zip(VIEW_TANGENTS, view.tangents)})
    return columns


def _pose_columns(prefix: str, pose: ConditionedPose) -> JsonObject:
    """Frame-log columns of one conditioned pose (see psyop.session.log.schema.pose_fields)."""
    (x, y, z), (qw, qx, qy, qz) = pose.position_m, pose.orientation_wxyz
    return {f"{prefix}_sample_t_s": pose.sample_t_s, f"{prefix}_x_m": x, f"{prefix}_y_m": y, f"{prefix}_z_m": z,
            f"{prefix}_qw": qw, f"{prefix}_qx": qx, f"{prefix}_qy": qy, f"{prefix}_qz": qz,
            f"{prefix}_valid": pose.valid, f"{prefix}_held": pose.held}


def pursuit_fields(path: FixationPath | None) -> JsonObject:
    """The :class:`LoopFacts` fields of the protocol's moving fixation target (``plan.fixation``); none
    without one (the defaults of :class:`LoopFacts` stand)."""
    if path is None:
        return {}
    return dict(pursuit_eccentricity_deg=path.eccentricity_deg, pursuit_speed_deg_s=path.speed_deg_s,
                pursuit_centre_deg=path.centre_deg, pursuit_id=path.id, pursuit_path=path)


def fixation_plan(c: LoopFacts, phase: PhaseSpec, row: TrialRow, start_s: float) -> FixationPlan:
    """Where the observer is asked to look in ``phase`` of trial ``row`` from ``start_s`` on: the pursuit
    target's path (the schedule fixes where it starts and which way it turns), the static fixation target
    (where this trial draws it), free viewing, or the cross. The loop sets it on the gaze source; psyop.quality rebuilds the target from it."""
    seed = int(row.get("trial_seed", 0)) & 0xFFFFFFFF
    if phase.gaze == "pursuit":
        start_key = f"{c.pursuit_id}_start_deg"  # the default's hash only when the schedule has no start
        phase_deg = float(row[start_key]) if start_key in row else float(seed_for("pursuit", seed) % 360)
        direction = -1.0 if float(row.get(f"{c.pursuit_id}_direction", 1)) < 0 else 1.0
        ecc, speed, centre = c.pursuit_eccentricity_deg, c.pursuit_speed_deg_s, c.pursuit_centre_deg
        if c.pursuit_path is not None:  # the trial's (interval's) levels, as the target is drawn
            path = c.pursuit_path
            if path.target is not None:  # a path without factors is its own for_values: no interval row built
                path = path.for_values(interval_values(row, max(1, phase.interval)))
            ecc, speed, centre = path.eccentricity_deg, path.speed_deg_s, path.centre_deg
        return FixationPlan("pursuit", start_s, c.fixation_distance_m, centre_deg=centre,
                            target=circling_target(ecc, direction * speed, phase_deg, centre))
    if phase.gaze == "fixate" and c.fixate_point is not None:  # the static target, where this trial draws it
        centre = c.fixate_point.centre_for(interval_values(row, max(1, phase.interval)))
        return FixationPlan("cross", start_s, c.fixation_distance_m, centre_deg=centre)
    if phase.gaze == "free":
        return FixationPlan("free", start_s, c.fixation_distance_m, radius_deg=c.free_radius_deg,
                            seed=seed_for(seed, phase.name))
    return FixationPlan("cross", start_s, c.fixation_distance_m)
