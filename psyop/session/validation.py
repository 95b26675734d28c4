"""Gaze validation in the headset (the protocol's ``gaze_validation:``, psyop.protocol.validation).

At the times the protocol says (the session's start, each change of block, the end) the loop calls
:meth:`GazeValidator.run`: each of the points is shown in turn (a head-fixed disc, :func:`validation_target_scene`)
for ``settle_s + dwell_s``; the tracker's samples of the last ``dwell_s`` give the point's accuracy (mean and
max angle between the gaze direction from the head origin and the target's) and precision (RMS
sample-to-sample and SD of the gaze angles, as pymovements' ``rms_s2s`` and ``std_rms``). Each attempt is
durable before anything is decided (validation.parquet; the raw samples go to gaze.parquet with trial -1).
With ``require``, an attempt over its bounds is run again, ``max_attempts`` in all; then
:class:`ValidationStopped` ends the session (exit 3, finalised incomplete, resumable).

A simulated tracker is told each target (a fixation plan on the point), so a headless session validates too.
Each target's onset is a ``phase`` event (trial -1, condition ``gaze_validation``, value ``validation_<i>``)
for the session's outside recorders (psyop.session.events).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np
import pandas as pd

from psyop import datacontract as dc
from psyop.optics.angles import angle_between_deg, fick_angles_deg, fick_direction
from psyop.protocol.validation import GazeValidation, ValidationRequirement
from psyop.session.events import SessionEvent
from psyop.session.gaze.plan import FixationPlan
from psyop.session.log.raw_gaze import raw_gaze_table
from psyop.session.log.validation_log import VALIDATION_SCHEMA, ValidationRecorder
from psyop.session.phases import PhaseSpec

if TYPE_CHECKING:
    from psyop.rendering.scene import Scene
    from psyop.session.clock import Clock
    from psyop.session.events import EventSink
    from psyop.session.frames import Display, DisplayInterrupted, FrameRenderer
    from psyop.session.gaze.sample import GazeSource
    from psyop.session.log.store import SessionLog


class _Regime(Protocol):
    @property
    def every_frame(self) -> bool: ...


class ValidationHost(Protocol):
    """What a validation uses of the trial loop (psyop.session.loop.TrialLoop), read only."""

    @property
    def clock(self) -> Clock: ...
    @property
    def gaze(self) -> GazeSource: ...
    @property
    def renderer(self) -> FrameRenderer | None: ...
    @property
    def display(self) -> Display: ...
    @property
    def store(self) -> SessionLog: ...
    @property
    def config(self) -> _Regime: ...
    @property
    def frame_period_s(self) -> float: ...
    @property
    def events(self) -> tuple[EventSink, ...]: ...
    def note_display_interruption(self, trial: int, exc: DisplayInterrupted) -> None: ...

#: a point with fewer valid samples than this has no accuracy or precision (NaN; an attempt then fails ``require``)
MIN_VALID_SAMPLES = 3


class ValidationStopped(Exception):
    """The protocol's ``require`` was not met in ``max_attempts`` validations: the session stops."""


@dataclass(frozen=True)
class TargetPhase(PhaseSpec):
    """A phase showing one validation target (``show`` 'target'): a disc ``target_size_deg`` across at Fick
    angles ``target_deg`` from the head origin, ``target_distance_m`` away."""

    target_deg: tuple[float, float] = (0.0, 0.0)
    target_distance_m: float = 1.0


def validation_phase(validation: GazeValidation, index: int) -> TargetPhase:
    """The phase that shows point ``index`` (the renderer draws :func:`validation_target_scene` for it)."""
    az, el = validation.points_deg[index]
    return TargetPhase(f"validation_{index}", validation.point_s, "target", "cross",
                     target_size_deg=float(validation.target_size_deg), target_deg=(float(az), float(el)),
                     target_distance_m=float(validation.distance_m))


def validation_target_scene(phase: TargetPhase) -> Scene:
    """A white disc ``target_size_deg`` across with a black centre (0.3 of it), facing the head origin, at
    ``target_distance_m`` along Fick angles ``target_deg`` from it, on the grey background."""
    from psyop.rendering import builders
    from psyop.rendering.scene import Scene, Shape, Solid

    az, el = phase.target_deg
    size, distance = phase.target_size_deg, phase.target_distance_m
    outer = builders.placed_primitive(Shape.DISC, distance, size, size, Solid((1.0, 1.0, 1.0)), az, el,
                                      facing="eye", name="validation_target")
    inner = builders.placed_primitive(Shape.DISC, distance, 0.3 * size, 0.3 * size, Solid((0.0, 0.0, 0.0)), az, el,
                                      facing="eye", name="validation_target_centre")  # coplanar, listed after: on top
    return Scene((outer, inner), background=(0.5, 0.5, 0.5))


def _precision_deg(az: np.ndarray, el: np.ndarray) -> tuple[float, float]:
    """(RMS sample-to-sample, SD) of gaze angles in degrees, as pymovements' ``rms_s2s`` and ``std_rms``
    (ddof 1; tests/session/test_gaze_validation.py compares them)."""
    if len(az) < MIN_VALID_SAMPLES:
        return math.nan, math.nan
    rms = math.sqrt(float(np.mean(np.diff(az) ** 2 + np.diff(el) ** 2)))
    return rms, math.sqrt(float(np.var(az, ddof=1) + np.var(el, ddof=1)))


def _eye_error_deg(samples: pd.DataFrame, eye: str, point_m: np.ndarray) -> float:
    """One eye's mean angle between its gaze normal and the line from its centre to the target (NaN where
    the tracker gives no such eye)."""
    centre = samples[[f"eye_centre_{eye}_{a}_m" for a in "xyz"]].to_numpy(dtype=np.float64)
    normal = samples[[f"gaze_normal_{eye}_{a}" for a in "xyz"]].to_numpy(dtype=np.float64)
    ok = np.all(np.isfinite(centre), axis=1) & np.all(np.isfinite(normal), axis=1)
    if ok.sum() < MIN_VALID_SAMPLES:
        return math.nan
    return float(np.mean(angle_between_deg(normal[ok], point_m[None, :] - centre[ok])))


def point_measures(samples: pd.DataFrame, start_s: float, end_s: float, target_deg: tuple[float, float],
                   distance_m: float) -> dict[str, float | int]:
    """Accuracy and precision of the raw samples (gaze.parquet columns) with ``start_s <= t < end_s`` on a
    target at Fick angles ``target_deg`` (from the head origin) and ``distance_m``."""
    t = samples[dc.GAZE_SAMPLE_T_S].to_numpy(dtype=np.float64)
    window = samples[(t >= start_s) & (t < end_s)]
    fixation = window[list(dc.FIXATION_COLUMNS)].to_numpy(dtype=np.float64)
    norm = np.linalg.norm(fixation, axis=1)
    ok = window[dc.GAZE_VALID].to_numpy(dtype=bool) & np.all(np.isfinite(fixation), axis=1) & (norm > 0)
    direction = fixation[ok] / norm[ok, None]
    target = fick_direction(*target_deg)
    error = np.asarray(angle_between_deg(direction, target), dtype=np.float64).reshape(-1)
    enough = len(error) >= MIN_VALID_SAMPLES
    az, el = (np.asarray(a, dtype=np.float64).reshape(-1) for a in fick_angles_deg(direction)) if enough \
        else (np.zeros(0), np.zeros(0))
    rms, sd = _precision_deg(az, el)
    point_m = distance_m * target
    valid_rows = window[ok]
    return {"n_samples": int(len(window)), "n_valid": int(ok.sum()),
            "mean_error_deg": float(error.mean()) if enough else math.nan,
            "max_error_deg": float(error.max()) if enough else math.nan,
            "precision_rms_s2s_deg": rms, "precision_sd_deg": sd,
            "left_mean_error_deg": _eye_error_deg(valid_rows, "left", point_m),
            "right_mean_error_deg": _eye_error_deg(valid_rows, "right", point_m)}


def overall_row(points: pd.DataFrame, requirement: ValidationRequirement | None) -> dict[str, float | int | bool]:
    """The attempt's overall row from its point rows: mean error over the points' mean errors, the largest
    sample error of any point, the points' mean precision; ``passed`` against ``requirement`` (no
    requirement: True; a point not measured fails it)."""
    mean_error = float(points["mean_error_deg"].mean()) if points["mean_error_deg"].notna().all() else math.nan
    passed = True
    if requirement is not None:
        passed = math.isfinite(mean_error) and mean_error <= requirement.max_mean_error_deg
        if requirement.max_point_error_deg is not None:
            passed = passed and bool((points["mean_error_deg"] <= requirement.max_point_error_deg).all())
    return {"point": -1, "target_az_deg": math.nan, "target_el_deg": math.nan,
            "start_s": float(points["start_s"].min()), "end_s": float(points["end_s"].max()),
            "n_samples": int(points["n_samples"].sum()), "n_valid": int(points["n_valid"].sum()),
            "mean_error_deg": mean_error, "max_error_deg": float(points["max_error_deg"].max()),
            "precision_rms_s2s_deg": float(points["precision_rms_s2s_deg"].mean()),
            "precision_sd_deg": float(points["precision_sd_deg"].mean()),
            "left_mean_error_deg": float(points["left_mean_error_deg"].mean()),
            "right_mean_error_deg": float(points["right_mean_error_deg"].mean()), "passed": bool(passed)}


@dataclass
class GazeValidator:
    """Runs the protocol's validations for one run of the loop; ``log`` keeps each attempt (durable in the session
    folder, or in psyop power's in-memory log; None: a log that keeps no samples, so nothing reads them)."""

    validation: GazeValidation
    log: ValidationRecorder | None = None
    n_run: int = 0  # validations run so far in this run (numbers the records)

    def close(self) -> None:
        if self.log is not None:
            self.log.close()

    def runs_at(self, when: str) -> bool:
        return when in self.validation.when

    def run(self, when: str, loop: ValidationHost, before_trial: int) -> pd.DataFrame:
        """One validation (attempts until ``require`` is met); its last attempt's rows. Raises
        :class:`ValidationStopped` when no attempt met it. At the ``end`` no trial waits for it: it runs once,
        ``passed`` says whether it met the bound, and the session completes."""
        requirement = self.validation.require
        attempts = requirement.max_attempts if requirement is not None and when != "end" else 1
        self.n_run += 1
        rows = pd.DataFrame()
        for attempt in range(1, attempts + 1):
            rows = self._attempt_on_display(loop, when, attempt, before_trial)
            if bool(rows["passed"].iloc[-1]) or when == "end":
                return rows
        assert requirement is not None  # without one every attempt passes
        last = rows.iloc[-1]
        raise ValidationStopped(
            f"gaze validation ({when}) failed {attempts} of {attempts} attempts (last: mean error "
            f"{last['mean_error_deg']:.2f} deg, largest point {rows['mean_error_deg'].iloc[:-1].max():.2f} deg; "
            f"gaze_validation.require allows {requirement.max_mean_error_deg:g} deg"
            + (f", {requirement.max_point_error_deg:g} deg per point" if requirement.max_point_error_deg else "")
            + "); the session stopped before the next trial: recalibrate the tracker, then rerun the same command "
              "to resume (validation.parquet has every attempt)")

    def _attempt_on_display(self, loop: ValidationHost, when: str, attempt: int, before_trial: int) -> pd.DataFrame:
        """One attempt once the display can show it (a headset session is FOCUSED only some time after it
        starts). An attempt the display interrupts (focus lost) is discarded, as an interrupted trial is: its
        raw samples are kept in gaze.parquet (trial -1), the interruption is recorded in session.json, and the
        attempt runs again once the display is ready; an interruption that ends the display ends the session."""
        from psyop.session.frames import DisplayInterrupted

        while True:
            loop.display.wait_until_ready()
            try:
                return self._attempt(loop, when, attempt, before_trial)
            except DisplayInterrupted as exc:
                samples = raw_gaze_table(loop.gaze.drain_raw(), run=loop.store.run_index, trial=-1)
                if loop.store.keeps_samples:
                    loop.store.append_gaze(samples, key=-1)
                loop.note_display_interruption(-1, exc)
                if not exc.rerun:
                    raise

    def _attempt(self, loop: ValidationHost, when: str, attempt: int, before_trial: int) -> pd.DataFrame:
        """Show every point, then make the attempt durable (raw samples, then its rows) and return its rows."""
        v = self.validation
        start_s = loop.clock.now_s()
        windows = []
        for index in range(len(v.points_deg)):
            phase = validation_phase(v, index)
            loop.gaze.set_plan(FixationPlan("cross", start_s, phase.target_distance_m, centre_deg=phase.target_deg))
            for sink in loop.events:  # outside recorders (LSL markers) see each target's onset
                sink.emit(SessionEvent("phase", -1, "gaze_validation", start_s, phase.name))
            hold_target(loop, phase, start_s)
            windows.append((start_s + float(v.settle_s), start_s + phase.duration_s, phase))
            start_s += phase.duration_s
        samples = raw_gaze_table(loop.gaze.drain_raw(), run=loop.store.run_index, trial=-1)
        if loop.store.keeps_samples:
            loop.store.append_gaze(samples, key=-1)
        frame = samples.to_pandas()
        points = pd.DataFrame([{"point": i, "target_az_deg": p.target_deg[0], "target_el_deg": p.target_deg[1],
                                "start_s": w0, "end_s": w1, "passed": True,
                                **point_measures(frame, w0, w1, p.target_deg, p.target_distance_m)}
                               for i, (w0, w1, p) in enumerate(windows)])
        rows = pd.concat([points, pd.DataFrame([overall_row(points, v.require)])], ignore_index=True)
        rows.insert(0, "run", loop.store.run_index)
        rows.insert(1, "validation", self.n_run)
        rows.insert(2, "when", when)
        rows.insert(3, "before_trial", before_trial)
        rows.insert(4, "attempt", attempt)
        rows["distance_m"] = float(v.distance_m)
        rows = rows[list(VALIDATION_SCHEMA.names)]
        if self.log is not None:
            self.log.append(rows, key=self.n_run)
        return rows


def gaze_validator(validation: GazeValidation | None, store: SessionLog) -> GazeValidator | None:
    """The validator of a run whose log ``store`` is open (None: the protocol has no ``gaze_validation:``)."""
    if validation is None:
        return None
    return GazeValidator(validation, store.validation_recorder())


def hold_target(loop: ValidationHost, phase: TargetPhase, start_s: float) -> list[float]:
    """Show ``phase``'s target from ``start_s`` for its duration, asking the tracker for gaze each frame:
    every frame rendered (a person watches) or, on the virtual clock without images, one poll per frame
    period (so a simulated tracker's requested stream has the samples to measure). Returns the session-clock
    time each frame was shown (its display time; a poll's time without images)."""
    end_s = start_s + phase.duration_s
    shown_s: list[float] = []
    t = start_s
    gaze_at = (0.0, 0.0, -phase.target_distance_m)  # the conventional camera ignores it
    row = {"trial": -1, "condition": "gaze_validation"}
    while t < end_s - 1e-9:
        if not loop.config.every_frame:
            loop.clock.sleep_until(t)
            loop.gaze.latest(loop.clock.now_s())
            shown_s.append(t)
            t += loop.frame_period_s
            continue
        request = loop.display.begin_frame(t)
        loop.gaze.latest(loop.clock.now_s())
        check = None
        if loop.renderer is not None and request.should_render:
            check = loop.renderer.render(row, phase, "conventional", request.display_time_s - start_s, gaze_at,
                                         frame=request)
        loop.display.end_frame(request, loop.renderer.eye_textures() if loop.renderer is not None else [])
        if check is not None and check.checked and not check.ok:
            raise RuntimeError(f"gaze validation point {phase.name}: rendered frame failed its check")
        shown_s.append(request.display_time_s)
        t = max(t + loop.frame_period_s, request.display_time_s + request.period_s)
    loop.clock.sleep_until(end_s)
    return shown_s
