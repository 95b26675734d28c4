"""The target the sample figure draws (issue 27 item 4) is the one psyop.quality measures the gaze against:
a gaze stream that follows the drawn path has no error, and the figure's dashed lines are that path."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from psyop.optics.angles import fick_direction
from psyop.protocol import load_protocol
from psyop.quality.figures import plot_sample_trials
from psyop.quality.measures import trial_measures
from psyop.quality.samples import gaze_grid
from psyop.quality.session import recorded_plan
from psyop.quality.target import target_path_deg
from psyop.schedule import compile_schedule
from psyop.run.runner import SessionOptions, run_session
from tests.session.session_helpers import small_protocol

RATE_HZ = 120.0


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory):
    directory = tmp_path_factory.mktemp("target")
    protocol = load_protocol(small_protocol(directory, "detection", 1))  # a cross, then pursuit phases
    options = SessionOptions(participant="T", seed=4, data_root=directory / "data", progress=False, render="cameras")
    assert run_session(protocol, compile_schedule, options).status == "complete"
    ses = directory / "data" / "detection" / "sub-T" / "ses-1"
    return pd.read_parquet(ses / "trials.parquet"), recorded_plan(ses)


def _following(path_deg: np.ndarray, t_s: np.ndarray) -> pd.DataFrame:
    """A gaze stream that looks exactly along ``path_deg`` (invalid where it is NaN)."""
    ok = np.all(np.isfinite(path_deg), axis=1)
    d = fick_direction(np.where(ok, path_deg[:, 0], 0.0), np.where(ok, path_deg[:, 1], 0.0))
    return pd.DataFrame({"gaze_sample_t_s": t_s, "gaze_valid": ok, "fixation_x_m": d[:, 0],
                         "fixation_y_m": d[:, 1], "fixation_z_m": d[:, 2]})


def test_gaze_along_the_target_path_has_no_error(session) -> None:
    trials, plan = session
    t_s = float(trials["trial_start_s"].min()) + np.arange(int(trials["trial_end_s"].max() * RATE_HZ)) / RATE_HZ
    path = target_path_deg(plan, trials, t_s)
    pursuit = {p.name for p in plan.phases if p.gaze == "pursuit"}
    assert pursuit and np.ptp(path[np.isfinite(path[:, 0]), 0]) > 10  # the circling path, not only the cross
    measures = trial_measures(gaze_grid(_following(path, t_s), RATE_HZ), trials, plan)[0]
    assert measures["accuracy_fixation_max_deg"].notna().all() and measures["accuracy_pursuit_max_deg"].notna().all()
    assert measures["accuracy_fixation_max_deg"].max() < 1e-6
    assert measures["accuracy_pursuit_max_deg"].max() < 1e-6
    # a target path off by 1 deg is measured as 1 deg off: the check can fail
    shifted = trial_measures(gaze_grid(_following(path + [1.0, 0.0], t_s), RATE_HZ), trials, plan)[0]
    assert shifted["accuracy_fixation_mean_deg"].to_numpy() == pytest.approx(1.0, abs=1e-6)


def test_the_sample_figure_draws_that_target(session) -> None:
    trials, plan = session
    rows = trials.head(3)
    start = float(rows["trial_start_s"].min())
    t_s = start + np.arange(int((float(rows["trial_end_s"].max()) - start) * RATE_HZ)) / RATE_HZ
    gaze = _following(target_path_deg(plan, rows, t_s), t_s)
    fig = plot_sample_trials(gaze, trials, plan)
    lines = {line.get_label(): line for line in fig.axes[0].get_lines()}
    for i, label in enumerate(("target azimuth (deg)", "target elevation (deg)")):
        x, y = (np.asarray(v, dtype=float) for v in lines[label].get_data())
        assert len(x) > 1000 and x[-1] == pytest.approx(float(rows["trial_end_s"].max()) - start, abs=2e-3)
        np.testing.assert_array_equal(y, target_path_deg(plan, rows, x + start)[:, i])
    assert "target azimuth (deg)" not in {line.get_label() for line in plot_sample_trials(gaze, trials).axes[0].get_lines()}
