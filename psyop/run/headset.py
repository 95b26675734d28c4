"""The in-headset tracker calibration of a run, wired between the backends and the loop.

A tracker that calibrates in the headset (``--tracker pupil:HOST:PORT,calibrate-hmd``) hands the assembly its
:class:`~psyop.session.headset_calibration.HeadsetCalibration` (``Backends.headset_calibration``).
:func:`calibrate_before_trials` makes a :class:`~psyop.session.headset_calibration.HeadsetCalibrator` of it (the
stated target layout, the eyes at the protocol's ipd), adds it to the loop's ``on_recalibrate`` (the experimenter's
"recalibrate now", ``c``: it runs between trials, before the protocol's gaze validation) and runs it once the log is
open and the renderer made, before the loop's first trial. A calibration that stopped the run is an outcome like
the loop's own (finalised incomplete, resumable); one that failed, at the start or on ``c``, is then a one-line
error naming the tracker's reason and the fix, exit code 2 (:func:`raise_if_calibration_failed`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pandas as pd

from psyop.errors import UserError
from psyop.session.frames import DisplayInterrupted
from psyop.session.gaze.sample import TrackerLost
from psyop.session.headset_calibration import (FAILURE_PREFIX, CalibrationLayout, HeadsetCalibrationFailed,
                                               HeadsetCalibrator, eye_centres_m)
from psyop.session.loop import SessionOutcome, TrialLoop

if TYPE_CHECKING:
    from psyop.run.assembly import Backends
    from psyop.session.plan import SessionPlan

__all__ = ["CALIBRATION_FAILED", "calibrate_before_trials", "headset_calibrator", "raise_if_calibration_failed"]

#: the outcome status of a run the in-headset calibration stopped before its first trial
CALIBRATION_FAILED = "calibration_failed"


def headset_calibrator(bundle: Backends, plan: SessionPlan,
                       layout: CalibrationLayout | None = None) -> HeadsetCalibrator | None:
    """The run's calibrator (None: the tracker calibrates nowhere in the headset)."""
    if bundle.headset_calibration is None:
        return None
    return HeadsetCalibrator(bundle.headset_calibration, eye_centres_m(plan.rig.ipd_m),
                             layout if layout is not None else CalibrationLayout())


def calibrate_before_trials(bundle: Backends, plan: SessionPlan, loop: TrialLoop, schedule: pd.DataFrame,
                            completed: set[int]) -> SessionOutcome | None:
    """Calibrate before the run's first trial (and hand the loop the calibrator for ``c``); None when it succeeded
    (or there is none), else the outcome that ends the run (the calibration failed, Ctrl-C, the tracker or the
    display lost)."""
    calibrator = headset_calibrator(bundle, plan)
    if calibrator is None:
        return None

    def recalibrate(host: TrialLoop, trial: int) -> None:  # c, between trials: before the gaze validation
        calibrator.run(host, "recalibrate", trial)

    loop.on_recalibrate.insert(0, recalibrate)
    remaining = [int(t) for t in schedule["trial"] if int(t) not in completed]
    n_recorded, n_total = len(completed), len(schedule)
    counted = f"{n_recorded}/{n_total} recorded"
    try:
        calibrator.run(loop, "start", remaining[0] if remaining else -1)
    except HeadsetCalibrationFailed as exc:
        return SessionOutcome(CALIBRATION_FAILED, n_recorded, n_total, f"{exc}; {counted}")
    except KeyboardInterrupt as exc:
        why = f"{exc}: " if str(exc) else ""
        return SessionOutcome("interrupted", n_recorded, n_total,
                              f"{why}interrupted during the in-headset calibration, {counted}")
    except TrackerLost as exc:
        return SessionOutcome("tracker_lost", n_recorded, n_total, f"{exc}; during the in-headset calibration, {counted}")
    except DisplayInterrupted as exc:
        return SessionOutcome("display_lost", n_recorded, n_total,
                              f"{exc.reason}; during the in-headset calibration, {counted}")
    return None


def raise_if_calibration_failed(outcome: SessionOutcome) -> None:
    """After the run is finalised: a failed calibration is a one-line error (exit code 2) naming the tracker's
    reason and the fix."""
    stopped_by_calibration = outcome.status == CALIBRATION_FAILED or (  # at the start, or on c (the loop's stop)
        outcome.status == "validation_failed" and outcome.message.startswith(FAILURE_PREFIX))
    if stopped_by_calibration:
        raise UserError(outcome.message, "--tracker")
