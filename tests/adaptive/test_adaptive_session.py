"""Adaptive levels in real (headless, simulated, virtual-clock) sessions."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from psyop.cli import main as cli_main
from psyop.errors import UserError
from psyop.protocol import load_protocol

ROOT = Path(__file__).resolve().parents[2]
DETECTION_LEVELS = r"(?m)^      levels: \[0, 0.25, 0.5, 0.75, 1\].*$"


def adaptive_detection(directory: Path, adaptive: str, repetitions: int, backs: str = "[1, 2, 3]",
                       between_sd: float = 0.05, name: str = "adaptive.yaml") -> Path:
    text = (ROOT / "protocols" / "detection.yaml").read_text()
    text, n = re.subn(DETECTION_LEVELS, f"      adaptive: {adaptive}", text)
    assert n == 1
    text = re.sub(r"(?m)^(\s*repetitions:)\s*\d+", rf"\g<1> {repetitions}", text)
    text = text.replace("levels: [1, 2, 3]", f"levels: {backs}", 1)
    text = re.sub(r"(?m)^(\s*between_subject_sd_D:)\s*[\d.]+", rf"\g<1> {between_sd}", text)
    path = directory / name
    path.write_text(text)
    return path


def _run(protocol: Path, data: Path, participant: str, seed: int = 5) -> pd.DataFrame:
    argv = ["run", str(protocol), "--participant", participant, "--seed", str(seed), "--data", str(data),
            "--clock", "virtual", "--no-progress", "--render", "cameras"]
    assert cli_main(argv) == 0
    study = load_protocol(protocol).study.name
    return pd.read_parquet(data / study / f"sub-{participant}" / "ses-1" / "trials.parquet")


def test_quest_plus_session_lands_near_the_observer_threshold(tmp_path: Path) -> None:
    protocol = adaptive_detection(tmp_path, "{procedure: quest_plus, start: 0.5, min: 0, max: 1.5}", 80,
                                  backs="[2]", between_sd=0.0)
    trials = _run(protocol, tmp_path / "data", "Q1")
    assert len(trials) == 80
    assert trials["level_D"].notna().all() and trials["level_D"].between(0, 1.5).all()
    assert (trials["adaptive_procedure"] == "quest_plus").all()
    assert trials["adaptive_trials"].tolist() == list(range(80))
    assert trials["level_D"].iloc[0] == 0.5  # start
    assert trials["level_D"].nunique() > 5  # placed, not constant
    final = trials.iloc[-1]
    # observer: threshold_D 0.36, width 0.2, lapse 0.02 (protocols/detection.yaml)
    assert final["adaptive_estimate_sd_D"] < 0.1
    assert abs(final["adaptive_estimate_D"] - 0.36) < 3 * final["adaptive_estimate_sd_D"] + 0.02
    assert trials["adaptive_estimate_sd_D"].iloc[-1] < trials["adaptive_estimate_sd_D"].iloc[0]


def test_interleaved_staircases_one_per_condition(tmp_path: Path) -> None:
    protocol = adaptive_detection(tmp_path, "{procedure: staircase, rule: 1u2d, start: 1.0, min: 0, max: 1.5, "
                                            "step_sizes: [0.2, 0.1]}", 20, backs="[1, 3]")
    trials = _run(protocol, tmp_path / "data", "S1")
    assert len(trials) == 40 and (trials["adaptive_procedure"] == "staircase_1u2d").all()
    assert trials["condition"].iloc[:20].nunique() == 2  # interleaved by the schedule
    for _, group in trials.groupby("condition"):
        assert group["adaptive_trials"].tolist() == list(range(20))
        assert group["level_D"].iloc[0] == 1.0
        steps = np.round(np.abs(np.diff(group["level_D"].to_numpy())), 9)
        assert set(steps) <= {0.0, 0.2, 0.1}
        assert group["adaptive_reversals"].is_monotonic_increasing


def test_the_worked_example_validates_and_runs(tmp_path: Path) -> None:
    path = ROOT / "protocols" / "examples" / "detection_quest_plus.yaml"
    protocol = load_protocol(path)
    assert protocol.design.factors["level_D"].adaptive.procedure == "quest_plus"
    trials = _run(path, tmp_path / "data", "E1")
    assert len(trials) == 120 and trials["level_D"].notna().all()
    last = trials.groupby("condition").tail(1)
    assert set(last["adaptive_trials"]) == {39}
    assert last["adaptive_estimate_D"].between(0, 1.5).all()


@pytest.mark.parametrize("adaptive,message", [
    ("{procedure: quest, start: 0.5, min: 0, max: 1.5}", "adaptive procedure 'quest' is not available"),
    ("{procedure: quest_plus, start: 0.5, min: 0, max: 1.5, rule: 1u3d}", "staircase settings"),
    ("{procedure: staircase, start: 0.5, min: 0, max: 1.5, grid_points: 51}", "quest_plus setting"),
    ("{procedure: staircase, start: 0.5, min: 0, max: 1.5, target: 0.8}", "rule: weighted"),
    ("{procedure: staircase, start: 2, min: 0, max: 1.5}", "min <= start <= max"),
])
def test_bad_adaptive_settings_are_refused(tmp_path: Path, adaptive: str, message: str) -> None:
    path = adaptive_detection(tmp_path, adaptive, 5)
    with pytest.raises(UserError, match=re.escape(message)):
        load_protocol(path)


def test_adaptive_factor_must_be_the_response_level(tmp_path: Path) -> None:
    text = (ROOT / "protocols" / "detection.yaml").read_text()
    text = text.replace("levels: [1, 2, 3]", "adaptive: {procedure: quest_plus, start: 2, min: 1, max: 3}", 1)
    path = tmp_path / "wrong.yaml"
    path.write_text(text)
    with pytest.raises(UserError, match="must be response.level_factor"):
        load_protocol(path)


def test_fits_accept_adaptive_levels_and_report_the_procedure_estimate(tmp_path: Path) -> None:
    from psyop.adaptive.results import final_estimates, with_procedure_estimates
    from psyop.statistics.psychometric import FitOptions, fit_psychometric_table

    protocol = adaptive_detection(tmp_path, "{procedure: quest_plus, start: 0.5, min: 0, max: 1.5}", 40,
                                  backs="[1, 2]", between_sd=0.0)
    trials = _run(protocol, tmp_path / "data", "F1")
    assert trials["level_D"].nunique() > 5  # off the constant-stimulus grid
    fits = fit_psychometric_table(trials, "level_D", ["participant", "back_D"], options=FitOptions(n_bootstrap=50))
    table = with_procedure_estimates(fits, trials, ["participant", "back_D"])
    assert len(table) == 2 and table["threshold_D"].notna().all()
    assert (table["procedure"] == "quest_plus").all() and (table["procedure_trials"] == 40).all()
    last = trials.sort_values("trial").groupby("back_D").tail(1).set_index("back_D")["adaptive_estimate_D"]
    assert table.set_index("back_D")["procedure_estimate_D"].to_dict() == last.to_dict()
    # psignifit and the procedure see the same trials: their thresholds agree within the CIs
    for _, row in table.iterrows():
        assert abs(row["threshold_D"] - row["procedure_estimate_D"]) < 2 * row["procedure_estimate_sd_D"] + 0.1
    with pytest.raises(ValueError, match="no adaptive levels"):
        final_estimates(trials.drop(columns="adaptive_procedure"), ["participant"])


def test_psyop_simulate_runs_an_adaptive_protocol(tmp_path: Path) -> None:
    protocol = adaptive_detection(tmp_path, "{procedure: staircase, start: 1.0, min: 0, max: 1.5}", 3, backs="[1]")
    data = tmp_path / "data"
    assert cli_main(["simulate", "--protocols", str(protocol), "--data", str(data), "--jobs", "1"]) == 0
    sessions = sorted((data / "detection").glob("sub-*/ses-1/trials.parquet"))
    assert len(sessions) == 6  # detection: the paper's six
    renamed = tmp_path / "renamed.yaml"  # a study without a paper size takes --participants too (was: always 6)
    renamed.write_text(protocol.read_text().replace("name: detection\n", "name: detection_staircase\n", 1))
    assert cli_main(["simulate", "--protocols", str(renamed), "--data", str(data), "--jobs", "1",
                     "--participants", "2"]) == 0
    assert len(sorted((data / "detection_staircase").glob("sub-*/ses-1/trials.parquet"))) == 2
    for path in sessions:
        trials = pd.read_parquet(path)
        assert len(trials) == 3 and trials["level_D"].notna().all()
        assert (trials["adaptive_procedure"] == "staircase_1u3d").all()
