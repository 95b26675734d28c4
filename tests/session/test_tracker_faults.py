"""Simulated tracker faults: NaN bursts and 500 ms dropouts hold the last gaze, flagged."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
from session_helpers import fast_protocol

from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.session.gaze.filter import GazeConditioner
from psyop.session.gaze.plan import FixationPlan
from psyop.session.gaze.sample import GazeSample
from psyop.session.gaze.simulated import SimulatedTracker, SimulatedTrackerConfig, angular_error_deg
from psyop.run.runner import SessionOptions, run_session


def test_conditioner_holds_last_valid_gaze_and_flags_it() -> None:
    conditioner = GazeConditioner(confidence_threshold=0.6)
    first = conditioner.condition(GazeSample(0.0, (0.1, 0.0, -1.0), 0.9, True))
    assert first.valid and not first.held
    for bad in [GazeSample(0.01, (math.nan, 0.0, -1.0), 0.9, True), GazeSample(0.02, (0.3, 0.0, -1.0), 0.2, True),
                GazeSample(0.03, (0.0, 0.0, 0.5), 0.9, True), GazeSample(0.04, (0.3, 0.0, -1.0), 0.9, False), None]:
        held = conditioner.condition(bad)
        assert held.held and not held.valid
        assert held.fixation_m == first.fixation_m and held.sample_t_s == 0.0


def test_dropouts_deliver_nothing_for_500_ms() -> None:
    tracker = SimulatedTracker(11, SimulatedTrackerConfig(dropout_rate_hz=0.5, dropout_s=0.5, blink_rate_hz=0))
    times = np.arange(0.02, 60.0, 1 / 90)
    ages = np.array([t - tracker.latest(t).timestamp_s for t in times])
    assert ages.max() > 0.45  # the sample in hand goes stale during a dropout ...
    stale = np.mean(ages > 0.1)  # Poisson dropouts cover 1 - exp(-0.5 * 0.5) = 22 % of the time
    assert 0.12 < stale < 0.35
    assert np.median(ages) < 0.02  # ... and is fresh otherwise (10 ms latency + tick)


def test_session_continues_through_nan_bursts_and_dropouts(tmp_path: Path) -> None:
    protocol = load_protocol(fast_protocol(tmp_path, "detection", 1, phase_s=0.5))  # 2 s per trial
    faults = SimulatedTrackerConfig(nan_burst_rate_hz=1.0, nan_burst_s=0.1, dropout_rate_hz=0.3, dropout_s=0.5)
    options = SessionOptions(participant="F1", seed=9, data_root=tmp_path / "data", progress=False,
                             tracker_faults=faults, every_frame=True, render="cameras")
    outcome = run_session(protocol, compile_schedule, options)
    assert outcome.status == "complete"
    session = tmp_path / "data" / "detection" / "sub-F1" / "ses-1"
    frames = pd.read_parquet(session / "frames.parquet")
    trials = pd.read_parquet(session / "trials.parquet")
    assert len(trials) == 15
    assert len(frames) == 15 * round(2.0 * 90)  # every frame of every trial, none lost
    held = frames[frames["gaze_held"]]
    assert 0.01 < len(held) / len(frames) < 0.5
    # a held frame renders the last valid fixation: finite, and equal to the frame before it
    assert frames[["fixation_x_m", "fixation_y_m", "fixation_z_m"]].notna().all().all()
    prev = frames.shift(1)
    same = held.index[held.index > 0]
    same = [i for i in same if frames.at[i, "trial"] == prev.at[i, "trial"]]
    np.testing.assert_array_equal(frames.loc[same, "fixation_x_m"], prev.loc[same, "fixation_x_m"])
    # dropouts make the held gaze old; the summary reports the age distribution of live frames
    assert held["sample_age_s"].max() > 0.3
    assert outcome.latency["sample_age_p99_ms"] <= 100.0 + 1e-9
    assert outcome.latency["n_frames_held"] == len(held)


def test_error_after_single_point_recalibration_is_about_1_2_deg() -> None:
    """The supplement measured 1.18 deg on average at the centre and 15 deg (after recalibration)."""
    errors = []
    for seed in range(40):
        tracker = SimulatedTracker(seed, SimulatedTrackerConfig(blink_rate_hz=0))
        conditioner = GazeConditioner()
        tracker.set_plan(FixationPlan("cross", 0.0))
        conditioner.recalibrate(tracker.latest(0.5), np.array([0.0, 0.0, -1.0]))
        for k, (az, el) in enumerate([(0, 0), (0, 15), (0, -15), (15, 0), (-15, 0)]):
            start = 1.0 + k
            tracker.set_plan(FixationPlan("cross", start, centre_deg=(az, el)))
            sample = tracker.latest(start + 0.5)
            corrected = np.array(conditioner.correct(sample.fixation_m))
            errors.append((k, angular_error_deg(corrected, tracker.true_direction(start + 0.5))))
    table = pd.DataFrame(errors, columns=["position", "error_deg"])
    mean = float(table["error_deg"].mean())
    assert 1.0 < mean < 1.4, mean
    by_position = table.groupby("position")["error_deg"].mean()
    assert by_position.idxmin() == 0  # lowest at the centre
    assert by_position.max() < 1.8  # the supplement's worst position: 1.6 deg
