"""In-headset eye-tracker calibration: psyop shows the targets, the tracker fits its mapping from them.

A tracker that calibrates from reference points the application shows and reports (Pupil Capture's HMD
calibration, driven as Pupil Labs' hmd-eyes drives it: psyop.devices.gaze.pupil_hmd_calibration) implements
:class:`HeadsetCalibration`; psyop.run hands it to a :class:`HeadsetCalibrator`. :meth:`HeadsetCalibrator.run`
shows each target of a :class:`CalibrationLayout` in turn, in the headset, through the gaze validation's drawing
path (psyop.session.validation: a head-fixed disc, :func:`~psyop.session.validation.hold_target`), gives the tracker
each target's position (head space, m: x right, y up, -z forward) with the session-clock display times of the
frames that showed it after ``settle_s``, then asks for the tracker's verdict (:class:`CalibrationResult`).

Each attempt is recorded before anything is decided: the raw gaze samples go to gaze.parquet (trial -1, as a
validation's do), and this run's ``headset_calibrations`` in session.json (``runs[-1]``) get one entry: when, the
targets with their reference frames (count, first and last display time), the tracker's result, reason and
accuracy. Each target's onset is a ``phase`` event (trial -1, condition ``headset_calibration``, value
``hmd_calibration_<i>``), the result one more (value ``hmd_calibration_<status>``). A result other than
``successful`` raises :class:`HeadsetCalibrationFailed`, whose one-line message names the tracker's reason and
the fix; it is a :class:`~psyop.session.validation.ValidationStopped`, so a loop that stops on a failed
validation stops on it the same way (finalised incomplete, resumable).

Accuracy: a tracker that reports its own (``CalibrationResult.accuracy_deg``) has it recorded; Pupil Capture
computes none for HMD calibrations (its Accuracy_Visualizer skips HMD gazers), so there the accuracy is the
protocol's ``gaze_validation:`` that follows (validation.parquet).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal, Protocol

from psyop.optics.angles import fick_direction
from psyop.optics.nodal import eye_centre_m
from psyop.session.events import SessionEvent
from psyop.session.gaze.plan import FixationPlan
from psyop.session.log.raw_gaze import raw_gaze_table
from psyop.session.validation import TargetPhase, ValidationStopped, hold_target

if TYPE_CHECKING:
    from psyop.session.rows import JsonObject
    from psyop.session.validation import ValidationHost

Vec3 = tuple[float, float, float]
CalibrationStatus = Literal["successful", "failed", "timeout", "not_started"]

#: the condition of the calibration's events and raw gaze rows
CONDITION = "headset_calibration"
#: how every :class:`HeadsetCalibrationFailed` message begins
FAILURE_PREFIX = "in-headset calibration "


class CalibrationUnavailable(Exception):
    """The tracker could not run the calibration (did not start it, refused a message); the text says why
    and what to do. The calibrator records it as a ``not_started`` result."""


class HeadsetCalibrationFailed(ValidationStopped):
    """The in-headset calibration did not succeed: the session stops before the next trial."""


@dataclass(frozen=True)
class CalibrationResult:
    """The tracker's verdict. ``reason``: the tracker's own words where it gave any; ``fix``: what the
    experimenter can do (part of the stop message); ``accuracy_deg``: the tracker's own accuracy (None: it
    reports none); ``tracker``: which tracker and calibration ran (e.g. Capture's version and plugin);
    ``details``: what else the tracker sent (JSON values)."""

    status: CalibrationStatus
    reason: str
    tracker: str
    fix: str = ""
    accuracy_deg: float | None = None
    details: JsonObject = field(default_factory=dict)

    @property
    def succeeded(self) -> bool:
        return self.status == "successful"


class HeadsetCalibration(Protocol):
    """What a tracker calibrated in the headset implements (the calls come in this order, once per attempt).

    ``begin``: start the tracker's calibration; ``eye_centres_m`` are the (left, right) eyes' centres in head
    space (m). ``add_reference``: the participant looked at ``position_m`` (head space, m: x right, y up,
    -z forward) at each of ``times_s`` (session clock). ``finish``: stop, and wait at most ``timeout_s`` for
    the tracker's result. ``begin`` and ``add_reference`` raise :class:`CalibrationUnavailable` when the
    tracker cannot go on; ``finish`` always returns a result. ``close``: release what ``begin`` opened
    (idempotent; the session's teardown calls it)."""

    def begin(self, eye_centres_m: tuple[Vec3, Vec3]) -> None: ...

    def add_reference(self, position_m: Vec3, times_s: Sequence[float]) -> None: ...

    def finish(self, timeout_s: float) -> CalibrationResult: ...

    def close(self) -> None: ...


@dataclass(frozen=True)
class CalibrationTarget:
    """One target: Fick angles (azimuth, elevation) from the head origin, ``distance_m`` away."""

    target_deg: tuple[float, float]
    distance_m: float

    def position_m(self) -> Vec3:
        x, y, z = (float(v) for v in self.distance_m * fick_direction(*self.target_deg))
        return (x, y, z)


def circle_targets(eccentricity_deg: float = 10.0, n_ring: int = 8,
                   distances_m: tuple[float, ...] = (0.6, 1.0, 2.0)) -> tuple[CalibrationTarget, ...]:
    """The centre, then ``n_ring`` points ``eccentricity_deg`` out, evenly around it (the first to the right,
    counter-clockwise); target ``i`` at ``distances_m[i % len(distances_m)]``, so the depths alternate."""
    angles = [(0.0, 0.0)] + [(eccentricity_deg * math.cos(2 * math.pi * k / n_ring),
                               eccentricity_deg * math.sin(2 * math.pi * k / n_ring)) for k in range(n_ring)]
    return tuple(CalibrationTarget((round(az, 9), round(el, 9)), distances_m[i % len(distances_m)])
                 for i, (az, el) in enumerate(angles))


@dataclass(frozen=True)
class CalibrationLayout:
    """The stated targets and how each is shown: ``settle_s`` to look there (no reference data), then
    ``frames_per_target`` frames whose display times are the reference data; ``result_timeout_s``: the longest
    wait for the tracker's result once the targets are done.

    The default follows hmd-eyes and Pupil's HMD calibration example (pupil-helpers
    ``hmd_calibration_client.py``): a circle of 8 targets and the centre, at 0.6, 1 and 2 m, 60 samples each."""

    targets: tuple[CalibrationTarget, ...] = field(default_factory=circle_targets)
    settle_s: float = 0.5
    frames_per_target: int = 60
    target_size_deg: float = 1.5
    result_timeout_s: float = 30.0

    def describe(self) -> JsonObject:
        return {"settle_s": self.settle_s, "frames_per_target": self.frames_per_target,
                "target_size_deg": self.target_size_deg, "result_timeout_s": self.result_timeout_s}


def calibration_phase(layout: CalibrationLayout, index: int, frame_period_s: float) -> TargetPhase:
    """The phase that shows target ``index``: ``settle_s`` plus ``frames_per_target`` frame periods."""
    target = layout.targets[index]
    return TargetPhase(f"hmd_calibration_{index}", layout.settle_s + layout.frames_per_target * frame_period_s,
                       "target", "cross", target_size_deg=float(layout.target_size_deg),
                       target_deg=(float(target.target_deg[0]), float(target.target_deg[1])),
                       target_distance_m=float(target.distance_m))


def eye_centres_m(ipd_m: float) -> tuple[Vec3, Vec3]:
    """(left, right) eye centres of rotation in head space for an interpupillary distance (the one rule:
    psyop.optics.nodal.eye_centre_m)."""
    left, right = (tuple(float(v) for v in eye_centre_m(eye, ipd_m)) for eye in ("left", "right"))
    return (left[0], left[1], left[2]), (right[0], right[1], right[2])


@dataclass
class HeadsetCalibrator:
    """Runs the in-headset calibration of one run of the loop (see the module docstring); ``records``: this
    run's attempts as session.json keeps them."""

    calibration: HeadsetCalibration
    eye_centres_m: tuple[Vec3, Vec3]
    layout: CalibrationLayout = field(default_factory=CalibrationLayout)
    records: list[JsonObject] = field(default_factory=list)

    def run(self, host: ValidationHost, when: str, before_trial: int) -> CalibrationResult:
        """One calibration before trial ``before_trial`` (``when``: ``start``, ``recalibration``); its result.
        Raises :class:`HeadsetCalibrationFailed` when it did not succeed (recorded first)."""
        from psyop.session.frames import DisplayInterrupted

        while True:
            host.display.wait_until_ready()
            started_s = host.clock.now_s()
            references: list[JsonObject] = []
            try:
                self._show_targets(host, started_s, references)
            except DisplayInterrupted as exc:  # the attempt is void: the tracker is told to stop, then it reruns
                self._keep_raw_gaze(host)
                self.calibration.finish(self.layout.result_timeout_s)
                host.note_display_interruption(-1, exc)
                if not exc.rerun:
                    raise
                continue
            except CalibrationUnavailable as exc:
                result = self.calibration.finish(self.layout.result_timeout_s)  # stops what was started
                result = CalibrationResult("not_started", str(exc), result.tracker)
            else:
                result = self.calibration.finish(self.layout.result_timeout_s)
            self._keep_raw_gaze(host)
            self._record(host, when, before_trial, started_s, references, result)
            if not result.succeeded:
                raise HeadsetCalibrationFailed(failure_message(result, references))
            return result

    def _show_targets(self, host: ValidationHost, start_s: float, references: list[JsonObject]) -> None:
        """Begin, show every target, give the tracker each one's reference frames (each added to ``references``
        once the tracker took it)."""
        self.calibration.begin(self.eye_centres_m)
        start_s = max(start_s, host.clock.now_s())  # the first target from when the tracker is ready for it
        for index, target in enumerate(self.layout.targets):
            phase = calibration_phase(self.layout, index, host.frame_period_s)
            host.gaze.set_plan(FixationPlan("cross", start_s, phase.target_distance_m, centre_deg=phase.target_deg))
            for sink in host.events:
                sink.emit(SessionEvent("phase", -1, CONDITION, start_s, phase.name))
            shown_s = hold_target(host, phase, start_s)
            times_s = [t for t in shown_s if t >= start_s + self.layout.settle_s - 1e-9]
            position_m = target.position_m()
            self.calibration.add_reference(position_m, times_s)
            references.append({"target": index, "az_deg": target.target_deg[0], "el_deg": target.target_deg[1],
                               "distance_m": target.distance_m, "position_m": list(position_m),
                               "n_frames": len(times_s), "first_s": times_s[0] if times_s else None,
                               "last_s": times_s[-1] if times_s else None})
            start_s += phase.duration_s

    def _keep_raw_gaze(self, host: ValidationHost) -> None:
        samples = raw_gaze_table(host.gaze.drain_raw(), run=host.store.run_index, trial=-1)
        if host.store.keeps_samples:
            host.store.append_gaze(samples, key=-1)

    def _record(self, host: ValidationHost, when: str, before_trial: int, started_s: float,
                references: list[JsonObject], result: CalibrationResult) -> None:
        """The attempt into session.json (this run's ``headset_calibrations``) and the events."""
        ended_s = host.clock.now_s()
        self.records.append({
            "when": when, "before_trial": before_trial, "start_s": started_s, "end_s": ended_s,
            "layout": self.layout.describe(), "eye_centres_m": [list(c) for c in self.eye_centres_m],
            "references": references, "n_reference_frames": sum(int(r["n_frames"]) for r in references),
            "status": result.status, "reason": result.reason, "tracker": result.tracker,
            "accuracy_deg": result.accuracy_deg,
            "accuracy_source": "tracker" if result.accuracy_deg is not None else
            "none from the tracker: the gaze validation that follows (validation.parquet) measures it",
            "details": result.details})
        host.store.update_run(headset_calibrations=list(self.records))
        for sink in host.events:
            sink.emit(SessionEvent("phase", -1, CONDITION, ended_s, f"hmd_calibration_{result.status}"))


def failure_message(result: CalibrationResult, references: Sequence[JsonObject]) -> str:
    """One line: what failed, the tracker's reason, what was sent, the fix."""
    sent = sum(int(r["n_frames"]) for r in references)
    return (f"{FAILURE_PREFIX}{result.status}"
            + (f" ({result.tracker})" if result.tracker else "")
            + f": {result.reason or 'no reason given'}; {sent} reference frames sent for {len(references)} targets; "
            + (result.fix + "; " if result.fix else "")
            + "the session stopped before the next trial: rerun the same command to calibrate again and resume "
              "(session.json headset_calibrations has every attempt)")
