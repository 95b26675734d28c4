"""Precision within fixation segments (issue 43 item 6): a gaze stream psyop has not seen (built here, not
by the simulated tracker) with white noise of a known SD, a 6 deg saccade every 0.6 s and dropouts is
reported at the injected precision, not at the jumps between fixations.

White noise of SD ``sigma`` per axis, independent from sample to sample: a step between two successive
samples has variance 2 sigma^2 per axis, so the RMS sample-to-sample displacement (both axes) is
sqrt(2 sigma^2 + 2 sigma^2) = 2 sigma (sqrt(2) sigma per axis), and the radial SD about the fixation's
mean is sqrt(sigma^2 + sigma^2) = sqrt(2) sigma."""

from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd
import pytest

from psyop.optics.angles import fick_direction
from psyop.protocol import load_protocol
from psyop.quality.measures import trial_measures
from psyop.quality.samples import gaze_grid
from psyop.session.plan import compile_plan
from tests.session.session_helpers import small_protocol

RATE_HZ, SIGMA_DEG, DURATION_S = 120.0, 0.155, 30.0  # 2 sigma = 0.31 deg RMS-S2S (the stream)
SACCADE_EVERY_S, SACCADE_DEG, SACCADE_S = 0.6, 6.0, 0.04


def _stream(seed: int = 43) -> pd.DataFrame:
    """Fixations alternating between azimuth -3 and +3 deg (a 6 deg raised-cosine saccade every 0.6 s),
    white noise, 0.05 s dropouts at about 1 Hz and single lost samples (1 %)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(DURATION_S * RATE_HZ)) / RATE_HZ
    k, into = np.divmod(t, SACCADE_EVERY_S)
    side = np.where(k % 2 == 0, -1.0, 1.0)
    ramp = np.clip(into / SACCADE_S, 0.0, 1.0)
    moved = 0.5 * (1 - np.cos(np.pi * ramp))  # 0 -> 1 over the saccade
    az = np.where(k == 0, -3.0, -side * 3.0 + side * SACCADE_DEG * moved)
    el = np.full_like(t, 1.0)
    az, el = az + rng.normal(0, SIGMA_DEG, len(t)), el + rng.normal(0, SIGMA_DEG, len(t))
    lost = rng.random(len(t)) < 0.01
    for onset in rng.uniform(0, DURATION_S, int(DURATION_S)):
        lost |= (t >= onset) & (t < onset + 0.05)
    d = fick_direction(az, el)
    frame = pd.DataFrame({"gaze_sample_t_s": t, "gaze_valid": ~lost, "fixation_x_m": d[:, 0],
                          "fixation_y_m": d[:, 1], "fixation_z_m": d[:, 2]})
    return frame[rng.random(len(t)) > 0.005]  # a few samples missing altogether (gaps on the grid)


@pytest.fixture(scope="module")
def measured(tmp_path_factory: pytest.TempPathFactory):
    path = small_protocol(tmp_path_factory.mktemp("precision"), "detection", 1)
    text, n = re.subn(r"(?m)^(\s*expected_s:)\s*1\.0", rf"\g<1> {DURATION_S}", path.read_text(), count=1)
    assert n == 1
    path.write_text(text)
    plan = compile_plan(load_protocol(path))
    assert plan.phases[0].gaze == "cross" and plan.phases[0].duration_s == DURATION_S
    trials = pd.DataFrame({"trial": [0], "trial_start_s": [0.0], "trial_end_s": [DURATION_S], "trial_seed": [1]})
    grid = gaze_grid(_stream(), RATE_HZ)
    table, events = trial_measures(grid, trials, plan)
    return table.iloc[0], events, grid


def test_precision_is_the_injected_noise_not_the_saccades(measured) -> None:
    row, events, _ = measured
    # the jumps are seen (some fall into a dropout)
    assert (events["name"] == "saccade").sum() >= 0.75 * DURATION_S / SACCADE_EVERY_S
    assert row["precision_rms_s2s_deg"] == pytest.approx(2 * SIGMA_DEG, rel=0.2)
    assert row["precision_sd_deg"] == pytest.approx(math.sqrt(2) * SIGMA_DEG, rel=0.2)


def _segments(events: pd.DataFrame, grid) -> np.ndarray:
    """Segment number per grid tick (-1: not in one): valid, outside every saccade, split at missing ticks."""
    t = grid.t_s
    keep = grid.valid & (t < DURATION_S)
    for onset, offset in events.loc[events["name"] != "fixation", ["onset_s", "offset_s"]].itertuples(index=False):
        keep &= ~((t >= onset) & (t <= offset))
    starts = keep & ~np.concatenate([[False], keep[:-1]])
    return np.where(keep, np.cumsum(starts) - 1, -1)


def test_pooled_precision_equals_pymovements_per_segment(measured) -> None:
    """Each segment's pymovements rms_s2s and std_rms, pooled with weights n - 1 (the segment's steps and
    degrees of freedom), is what psyop reports."""
    import polars as pl
    from pymovements.measure.samples import rms_s2s, std_rms

    row, events, grid = measured
    segment = _segments(events, grid)
    inside = segment >= 0
    frame = pl.DataFrame({"segment": segment[inside],
                          "position": np.stack([grid.az_deg[inside], grid.el_deg[inside]], axis=1).tolist()})
    per = frame.group_by("segment").agg(rms_s2s(column="position"), std_rms(column="position"), pl.len().alias("n"))
    per = per.filter(pl.col("n") >= 2)
    weight = per["n"].to_numpy() - 1.0
    rms = math.sqrt(float(np.sum(weight * per["rms_s2s"].to_numpy() ** 2) / weight.sum()))
    sd = math.sqrt(float(np.sum(weight * per["std_rms"].to_numpy() ** 2) / weight.sum()))
    assert row["precision_rms_s2s_deg"] == pytest.approx(rms, rel=1e-9)
    assert row["precision_sd_deg"] == pytest.approx(sd, rel=1e-9)
