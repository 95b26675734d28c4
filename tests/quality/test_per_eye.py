"""Per-eye accuracy (issue 27): where the tracker gives each eye's centre and gaze normal, psyop measures
each eye against the line from its own centre to the cross."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from psyop.optics.angles import fick_direction
from psyop.protocol import load_protocol, parse_protocol
from psyop.quality.measures import trial_measures
from psyop.quality.samples import gaze_grid
from psyop.schedule import compile_schedule
from psyop.session.loop import LoopConfig, pursuit_fields
from psyop.session.plan import compile_plan
from psyop.run.runner import SessionOptions, run_session
from tests.session.session_helpers import small_protocol

ERROR_RIGHT_DEG = 1.0


def _rotate_about_y(v: np.ndarray, deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.stack([c * v[:, 0] + s * v[:, 2], v[:, 1], -s * v[:, 0] + c * v[:, 2]], axis=1)


def test_each_eye_is_measured_from_its_own_centre(tmp_path) -> None:
    protocol = load_protocol(small_protocol(tmp_path, "detection", 1))
    options = SessionOptions(participant="E", seed=2, data_root=tmp_path / "data", progress=False, render="cameras")
    assert run_session(protocol, compile_schedule, options).status == "complete"
    ses = tmp_path / "data" / "detection" / "sub-E" / "ses-1"
    gaze, trials = pd.read_parquet(ses / "gaze.parquet"), pd.read_parquet(ses / "trials.parquet")
    plan = compile_plan(parse_protocol(json.loads((ses / "session.json").read_text())["protocol_text"]))
    distance_m = LoopConfig(**pursuit_fields(plan.fixation)).fixation_distance_m  # as psyop.quality rebuilds it
    target = distance_m * fick_direction(0.0, 0.0)  # the cross: straight ahead at the plan's distance
    for eye, x_m, error_deg in (("left", -0.032, 0.0), ("right", 0.032, ERROR_RIGHT_DEG)):
        centre = np.tile([x_m, 0.0, 0.0], (len(gaze), 1))
        normal = _rotate_about_y(target - centre, error_deg)
        for i, axis in enumerate("xyz"):
            gaze[f"eye_centre_{eye}_{axis}_m"] = centre[:, i]
            gaze[f"gaze_normal_{eye}_{axis}"] = normal[:, i] / np.linalg.norm(normal, axis=1)
    measures = trial_measures(gaze_grid(gaze, 120.0), trials, plan)[0]  # at the simulated tracker rate
    measured = measures.dropna(subset=["accuracy_fixation_left_mean_deg"])
    assert len(measured) > 0
    assert measured["accuracy_fixation_left_mean_deg"].max() == pytest.approx(0.0, abs=1e-6)
    assert measured["accuracy_fixation_right_mean_deg"].to_numpy() == pytest.approx(ERROR_RIGHT_DEG, abs=1e-6)


def test_no_per_eye_data_gives_nan_not_a_number(tmp_path) -> None:
    grid = gaze_grid(pd.DataFrame({"gaze_sample_t_s": [0.0, 0.01], "gaze_valid": [True, True],
                                   "fixation_x_m": [0.0, 0.0], "fixation_y_m": [0.0, 0.0],
                                   "fixation_z_m": [-1.0, -1.0]}), 100.0)
    assert grid.eyes == {} and grid.eye_centres_m == {}
