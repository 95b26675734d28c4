"""SIGKILL an adaptive session at random moments: after each resume the procedure is rebuilt from
the logged trials, so the levels and responses equal an uninterrupted session's.

Kills as in tests/session/test_crash_safety.py: a forked `psyop run` with a small real delay per
phase, killed after a random time; the child announces each trial only after its durable append.
"""

from __future__ import annotations

import json
import random
import sys
from pathlib import Path

import pandas as pd
import pytest

from psyop.cli import main as cli_main
from psyop.session.log.layout import SessionPaths

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_adaptive_session import adaptive_detection

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "session"))
from kill_helpers import kill_once, run_args

SEED = 9
COMPARED = ["trial", "condition", "level_D", "correct", "response", "adaptive_procedure", "adaptive_trials",
            "adaptive_estimate_D", "adaptive_estimate_sd_D", "adaptive_step_D", "adaptive_reversals"]


@pytest.mark.slow
@pytest.mark.parametrize("adaptive", [
    "{procedure: quest_plus, start: 0.5, min: 0, max: 1.5, grid_points: 51}",
    "{procedure: staircase, rule: weighted, target: 0.75, start: 1.0, min: 0, max: 1.5, step_sizes: [0.1, 0.05]}",
    # the stop rule: conditions stop early (target SD), their remaining trials are skipped alike after resumes
    "{procedure: quest_plus, start: 0.5, min: 0, max: 1.5, grid_points: 51, target_sd: 0.2}",
])
def test_sigkill_gives_the_levels_of_an_uninterrupted_run(tmp_path: Path, adaptive: str) -> None:
    protocol = adaptive_detection(tmp_path, adaptive, 12, backs="[1, 3]")
    reference = tmp_path / "reference"
    assert cli_main(run_args(protocol, reference, "K1", SEED, 0.0)) == 0
    expected = pd.read_parquet(SessionPaths(reference, "detection", "K1", 1).trials_parquet)
    expected_meta = json.loads(SessionPaths(reference, "detection", "K1", 1).metadata.read_text())
    n = len(expected)
    if "target_sd" in adaptive:
        stop = expected_meta["adaptive_stop"]  # seed 9: both conditions stop early, trials 17, 19-23 not run
        assert n == 18 and stop["n_trials_not_run"] == 6 and {c["reason"] for c in stop["conditions"].values()} == {"target_sd"}
    else:
        assert n == 24

    data = tmp_path / "killed"
    paths = SessionPaths(data, "detection", "K1", 1)
    rng = random.Random(4321)
    kills, announced_total, progressed = 0, set(), 0
    while kills < 60 and len(announced_total) < n:
        # a third of the kills at a random moment from the start (they may hit start-up or resume),
        # the rest a random moment after the run's first new durable trial (inside the session on
        # any machine load); either way the moment is random within a trial's phases
        early = rng.random() < 1 / 3
        announced = kill_once(run_args(protocol, data, "K1", SEED, 0.01),
                              rng.uniform(0.0, 0.3) if early else rng.uniform(0.0, 0.08),
                              after_trials=0 if early else 1)
        kills += 1
        progressed += bool(announced - announced_total)
        announced_total |= announced
    assert kills >= 10 and progressed >= 3, (kills, progressed)
    if json.loads(paths.metadata.read_text()).get("status") != "complete":  # a kill may land after the end
        assert cli_main(run_args(protocol, data, "K1", SEED, 0.0)) == 0  # resume to the end
    final = pd.read_parquet(paths.trials_parquet)
    assert final["trial"].tolist() == expected["trial"].tolist()
    meta = json.loads(paths.metadata.read_text())
    assert meta["status"] == "complete" and meta["adaptive_stop"] == expected_meta["adaptive_stop"]
    pd.testing.assert_frame_equal(final[COMPARED].reset_index(drop=True), expected[COMPARED].reset_index(drop=True),
                                  check_dtype=False)
