"""The session-wide pieces of the gaze-quality path equal the per-trial forms they replace, exactly: grouped
medians and maxima (numpy's np.median and np.max of each trial's values), the recorded-sample check (the former
pandas merge), and a raw stream whose per-eye normals are all missing places no eye."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from psyop.quality.measures import _max_by_row, _median_by_row
from psyop.quality.resimulate import TOLERANCE_M, check_against_recorded
from psyop.quality.samples import gaze_grid
from psyop.session.gaze.simulated import _EventTimes

pytestmark = pytest.mark.cross_cpu  # grouped and per-trial forms on this CPU's kernels, compared exactly


def _groups(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Values of 60 trials in trial order (sizes 0 to 9, odd and even, some trials empty) and their bounds."""
    counts = rng.integers(0, 10, 60)
    counts[:3] = (0, 1, 2)
    values = rng.normal(0.0, 3.0, int(counts.sum()))
    values[rng.integers(0, len(values), 5)] = rng.choice([-1.5, 0.0, 2.25], 5)  # ties
    return values, np.concatenate([[0], np.cumsum(counts)])


def test_grouped_medians_and_maxima_equal_numpy_per_trial() -> None:
    rng = np.random.default_rng(5)
    for _ in range(20):
        values, bounds = _groups(rng)
        if rng.uniform() < 0.5:  # a NaN makes its trial's median and maximum NaN, as np.median and np.max
            values[rng.integers(0, len(values))] = np.nan
        medians, maxima = _median_by_row(values, bounds), _max_by_row(values, bounds)
        for r, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
            part = values[a:b]
            expected = (float(np.median(part)), float(np.max(part))) if len(part) else (math.nan, math.nan)
            for got, want in zip((medians[r], maxima[r]), expected):
                assert got == want or (math.isnan(got) and math.isnan(want)), (r, part, got, want)


def _former_check(rebuilt: pd.DataFrame, recorded: pd.DataFrame, rate_hz: float) -> tuple[int, int, float]:
    """The recorded-sample check as a pandas merge (run, tick) of the recorded rows with the rebuilt ones
    (first of each key), over rows already inside the trial windows."""
    axes = [f"fixation_{a}_m" for a in "xyz"]

    def keyed(frame: pd.DataFrame) -> pd.DataFrame:
        tick = np.rint(frame["gaze_sample_t_s"].to_numpy(float) * rate_hz).astype(np.int64)
        return frame.assign(tick=tick)[["run", "tick", "gaze_valid", *axes]]

    both = keyed(recorded).merge(keyed(rebuilt).drop_duplicates(["run", "tick"]), on=["run", "tick"], how="left",
                                 suffixes=("", "_rebuilt"), indicator=True)
    found = (both["_merge"] == "both").to_numpy()
    same_valid = found & (both["gaze_valid"].to_numpy() == both["gaze_valid_rebuilt"].to_numpy())
    diff = np.stack([np.abs(both[a].to_numpy(float) - both[f"{a}_rebuilt"].to_numpy(float)) for a in axes], axis=1)
    nan_both = np.stack([np.isnan(both[a].to_numpy(float)) & np.isnan(both[f"{a}_rebuilt"].to_numpy(float))
                         for a in axes], axis=1)
    agree = same_valid & np.all(nan_both | (diff <= TOLERANCE_M), axis=1)
    finite = diff[found & ~np.any(nan_both, axis=1)]
    return int(len(both)), int((~agree).sum()), float(np.max(finite)) if finite.size else math.nan


def _stream(rng: np.random.Generator, ticks: np.ndarray, runs: np.ndarray, rate_hz: float) -> pd.DataFrame:
    valid = rng.uniform(size=len(ticks)) > 0.1
    xyz = rng.normal(0.0, 0.3, (len(ticks), 3))
    xyz[~valid] = np.nan
    return pd.DataFrame({"gaze_sample_t_s": ticks / rate_hz, "run": runs, "gaze_valid": valid,
                         "fixation_x_m": xyz[:, 0], "fixation_y_m": xyz[:, 1], "fixation_z_m": xyz[:, 2]})


def test_the_recorded_sample_check_equals_the_former_merge() -> None:
    rng, rate = np.random.default_rng(8), 120.0
    ticks = np.concatenate([np.arange(0, 600), np.arange(0, 400), np.arange(250, 300)])  # a duplicated stretch
    runs = np.concatenate([np.zeros(600, dtype=np.int64), np.ones(400, dtype=np.int64), np.zeros(50, dtype=np.int64)])
    rebuilt = _stream(rng, ticks, runs, rate)
    trials = pd.DataFrame({"trial_start_s": [0.0, 0.0, 0.0], "trial_end_s": [1000.0] * 3, "run": [0, 1, 5]})
    pick = np.sort(rng.choice(len(rebuilt) - 50, 120, replace=False))
    recorded = rebuilt.iloc[pick].reset_index(drop=True)
    bad = recorded.copy()
    bad.loc[[3, 9], "fixation_x_m"] += 1e-3  # off by a millimetre
    bad.loc[20, "gaze_valid"] = not bad.loc[20, "gaze_valid"]
    bad.loc[30, "run"] = 5  # a run the rebuild does not hold
    bad.loc[40, "gaze_sample_t_s"] += 7.0  # a tick past the rebuilt ones
    bad.loc[50, "fixation_y_m"] = np.nan  # NaN on one side only
    for frame, disagreeing in ((recorded, 0), (bad, 6)):
        now = check_against_recorded(rebuilt, frame, trials, rate)
        former = _former_check(rebuilt, frame, rate)
        assert now[:2] == former[:2] == (len(frame), disagreeing)
        assert now[2] == former[2] or (math.isnan(now[2]) and math.isnan(former[2]))
    nothing = check_against_recorded(rebuilt.iloc[0:0], recorded, trials, rate)
    assert nothing[:2] == (len(recorded), len(recorded)) and math.isnan(nothing[2])


def test_a_stream_without_valid_eye_normals_places_no_eye() -> None:
    n = 50
    gaze = pd.DataFrame({"gaze_sample_t_s": np.arange(n) / 100.0, "gaze_valid": np.ones(n, dtype=bool),
                         "fixation_x_m": 0.0, "fixation_y_m": 0.0, "fixation_z_m": -1.0,
                         **{f"gaze_normal_{e}_{a}": np.nan for e in ("left", "right") for a in "xyz"},
                         **{f"eye_centre_{e}_{a}_m": 0.03 for e in ("left", "right") for a in "xyz"}})
    assert gaze_grid(gaze, 100.0).eyes == {}
    gaze.loc[7, ["gaze_normal_left_x", "gaze_normal_left_y", "gaze_normal_left_z"]] = (0.0, 0.0, -1.0)
    grid = gaze_grid(gaze, 100.0)
    assert set(grid.eyes) == {"left"} and np.isfinite(grid.eyes["left"][0]).sum() == 1
    assert np.isfinite(grid.eye_centres_m["left"]).all(axis=1).sum() == 1


def test_event_times_cover_what_a_mask_per_event_covers() -> None:
    """Blinks, NaN bursts and dropouts found by bisection cover the same times as one mask per event."""
    rng = np.random.default_rng(4)
    for seed, (rate_hz, duration_s) in enumerate([(0.25, 0.15), (3.0, 0.05), (0.5, 0.5), (2.0, 0.0)] * 3):
        events = _EventTimes(seed, 3, rate_hz, duration_s)
        for t_s in (np.arange(0, 9600) / 120.0, np.sort(rng.uniform(0.0, 80.0, 4000)), rng.uniform(0.0, 5.0, 200)):
            expected = np.zeros(len(t_s), dtype=bool)
            for w in range(int(math.floor(t_s[0] - duration_s)), int(math.floor(t_s[-1])) + 1):
                for start in events._starts(w):
                    expected |= (t_s >= start) & (t_s < start + duration_s)
            np.testing.assert_array_equal(events.covers(t_s), expected)
