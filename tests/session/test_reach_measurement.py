"""The simulated reach: the observer decides where the hand ends, the simulated tracker
measures it once (Vive Tracker accuracy per reach, precision per sample, paper sec. 4.3)."""

from __future__ import annotations

import numpy as np

from psyop.session.clock import VirtualClock
from psyop.session.loop import LoopConfig, TrialLoop
from psyop.session.pose import SimulatedPose, SimulatedPoseConfig
from psyop.session.responses.simulated import make_observer

OBSERVER = {"kind": "reach", "arm_reach_m": 0.7,
            "by_condition": {"enabled": {"slope": 1.0, "intercept_m": 0.1, "noise_sd_m": 0.03}}}


def _measured_minus_true(config: SimulatedPoseConfig, n: int = 300) -> np.ndarray:
    observer = make_observer(OBSERVER, seed=5, participant="S01")
    loop = TrialLoop(identity={"study": "t", "participant": "P", "session": 1}, phases=(), clock=VirtualClock(),
                     gaze=None, responses=None, renderer=None, display=None, store=None,  # type: ignore[arg-type]
                     config=LoopConfig(progress=False, hand_last_n=10), pose=SimulatedPose(11, config))
    errors = []
    for trial in range(n):
        row = {"trial": trial, "trial_seed": 1000 + trial, "rendering": "enabled", "target_fraction": 0.75}
        true = observer.collect(row, 0.0)
        measured, _ = loop._track_reach(row, true, end_s=5.0 * (trial + 1))
        errors.append(measured.reach_m - true.reach_m)
    return np.array(errors)


def test_a_perfect_tracker_measures_the_observers_reach_exactly() -> None:
    errors = _measured_minus_true(SimulatedPoseConfig(hand_accuracy_m=0.0, hand_precision_m=0.0))
    np.testing.assert_allclose(errors, 0.0, atol=1e-12)


def test_tracker_error_is_applied_once_at_the_vive_trackers_size() -> None:
    errors = _measured_minus_true(SimulatedPoseConfig())
    # per reach: accuracy 1.9 mm RMSE (3-D) plus the mean of 10 samples at 1.5 mm RMSE, of which
    # about one third of the variance lies along the reach direction
    expected_sd_m = np.sqrt((0.0019**2 + 0.0015**2 / 10) / 3)
    assert abs(errors.mean()) < 4 * expected_sd_m / np.sqrt(errors.size)
    assert 0.8 * expected_sd_m < errors.std() < 1.25 * expected_sd_m
