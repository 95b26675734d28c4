"""The adaptive stop rule in sessions (protocol ``target_sd``/``min_trials``; docs/adaptive.md):
a condition whose estimate's SD reaches the target runs no more trials; the session records why
and which trials were not run, and counts as complete."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import pandas as pd
import pytest

from psyop.cli import main as cli_main
from psyop.errors import UserError
from psyop.protocol import load_protocol
from psyop.session.log.layout import SessionPaths

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_adaptive_session import adaptive_detection

QUEST_STOP = "{procedure: quest_plus, start: 0.5, min: 0, max: 1.5, grid_points: 51, target_sd: 0.1}"
REPETITIONS = 60


def _run(protocol: Path, data: Path, participant: str, seed: int = 5) -> int:
    return cli_main(["run", str(protocol), "--participant", participant, "--seed", str(seed), "--data", str(data),
                     "--clock", "virtual", "--no-progress", "--render", "cameras"])


@pytest.fixture(scope="module")
def stopped_session(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, SessionPaths]:
    root = tmp_path_factory.mktemp("stop")
    protocol = adaptive_detection(root, QUEST_STOP, REPETITIONS, backs="[1, 3]")
    assert _run(protocol, root / "data", "T1") == 0
    return protocol, SessionPaths(root / "data", "detection", "T1", 1)


def test_quest_plus_stops_each_condition_at_its_target_sd(stopped_session: tuple[Path, SessionPaths]) -> None:
    _, paths = stopped_session
    trials = pd.read_parquet(paths.trials_parquet).sort_values("trial")
    meta = json.loads(paths.metadata.read_text())
    stop = meta["adaptive_stop"]
    assert meta["status"] == "complete" and meta["n_trials_scheduled"] == 2 * REPETITIONS
    assert len(trials) < 2 * REPETITIONS and meta["n_trials_recorded"] == len(trials)
    assert stop["target_sd"] == 0.1 and stop["n_trials_not_run"] == 2 * REPETITIONS - len(trials)
    assert meta["integrity"]["lost_trials"] == []  # left out by the stop rule, not lost
    schedule_trials = set(range(2 * REPETITIONS))
    not_run = {t for c in stop["conditions"].values() for t in c["trials_not_run"]}
    assert not_run | set(trials["trial"]) == schedule_trials and not not_run & set(trials["trial"])
    reasons = set()
    for condition, rows in trials.groupby("condition"):
        record = stop["conditions"][condition]
        reasons.add(record["reason"])
        sd = rows["adaptive_estimate_sd_D"].to_numpy()
        assert record["trials"] == len(rows) and record["estimate_sd_D"] == sd[-1]
        assert record["estimate_D"] == rows["adaptive_estimate_D"].iloc[-1]
        if record["reason"] == "target_sd":  # stopped early, at the first trial that reached the target
            assert len(rows) < REPETITIONS and sd[-1] <= 0.1 < sd[:-1].min()
            # the trials not run are exactly this condition's trials after its last recorded one
            assert len(record["trials_not_run"]) == REPETITIONS - len(rows)
            assert min(record["trials_not_run"]) > rows["trial"].max()
        else:  # ran its maximum without reaching the target
            assert record["reason"] == "max_trials" and len(rows) == REPETITIONS and sd.min() > 0.1
            assert record["trials_not_run"] == []
    assert reasons == {"target_sd", "max_trials"}  # seed 5: back 1 D stops early, back 3 D runs all 60


def test_a_stopped_session_is_complete_for_recover_resume_and_analysis(
        stopped_session: tuple[Path, SessionPaths], capsys: pytest.CaptureFixture[str]) -> None:
    from psyop.adaptive.results import with_procedure_estimates
    from psyop.statistics.dataset import load_dataset
    from psyop.statistics.psychometric import FitOptions, fit_psychometric_table

    protocol, paths = stopped_session
    paths.trials_parquet.unlink()  # recover rebuilds it from the log and must call the session complete
    capsys.readouterr()
    assert cli_main(["recover", str(paths.directory)]) == 0
    out = capsys.readouterr().out
    assert "complete" in out and "resumable" not in out and "not run: adaptive stop rule" in out
    assert json.loads(paths.metadata.read_text())["status"] == "complete"
    assert _run(protocol, paths.data_root, "T1") == 2  # complete: nothing to resume
    trials = load_dataset(paths.data_root, "detection").trials
    fits = fit_psychometric_table(trials, "level_D", ["participant", "back_D"], options=FitOptions(n_bootstrap=20))
    table = with_procedure_estimates(fits, trials, ["participant", "back_D"])
    assert len(table) == 2 and table["threshold_D"].notna().all()
    assert (table["procedure_trials"] < REPETITIONS).any() and (table["procedure_estimate_sd_D"] <= 0.1).any()


def test_without_target_sd_every_scheduled_trial_runs(tmp_path: Path) -> None:
    protocol = adaptive_detection(tmp_path, "{procedure: quest_plus, start: 0.5, min: 0, max: 1.5, grid_points: 51}",
                                  8, backs="[1, 3]")
    assert _run(protocol, tmp_path / "data", "N1") == 0
    meta = json.loads(SessionPaths(tmp_path / "data", "detection", "N1", 1).metadata.read_text())
    assert meta["n_trials_recorded"] == 16 and meta["adaptive_stop"]["n_trials_not_run"] == 0
    assert {c["reason"] for c in meta["adaptive_stop"]["conditions"].values()} == {"max_trials"}


def test_min_trials_delays_the_stop(tmp_path: Path) -> None:
    adaptive = QUEST_STOP.replace("}", ", min_trials: 45}")
    protocol = adaptive_detection(tmp_path, adaptive, REPETITIONS, backs="[1]")
    assert _run(protocol, tmp_path / "data", "M1") == 0
    trials = pd.read_parquet(SessionPaths(tmp_path / "data", "detection", "M1", 1).trials_parquet)
    assert 45 <= len(trials) < REPETITIONS  # 23 trials reach SD 0.1 for back 1 D without min_trials


@pytest.mark.parametrize("adaptive,message", [
    ("{procedure: quest_plus, start: 0.5, min: 0, max: 1.5, target_sd: 0.5}", "not below the SD of the estimate's uniform prior"),
    ("{procedure: quest_plus, start: 0.5, min: 0, max: 1.5, min_trials: 5}", "give target_sd or drop min_trials"),
    ("{procedure: staircase, start: 0.5, min: 0, max: 1.5, target_sd: 0}", "greater than 0"),
    ("{procedure: staircase, start: 0.5, min: 0, max: 1.5, target_sd: 0.1, min_trials: 0}", "must be at least 1"),
])
def test_bad_stop_settings_are_refused_with_their_line(tmp_path: Path, adaptive: str, message: str) -> None:
    path = adaptive_detection(tmp_path, adaptive, 5)
    line = next(i for i, text in enumerate(path.read_text().splitlines(), 1) if "adaptive:" in text)
    with pytest.raises(UserError, match=re.escape(message)) as error:
        load_protocol(path)
    assert f":{line}" in str(error.value)


def test_psyop_simulate_and_power_run_a_stopping_protocol(tmp_path: Path) -> None:
    from psyop.power.run import PowerRun, run_power

    protocol = adaptive_detection(tmp_path, QUEST_STOP, 40, backs="[1, 3]")
    data = tmp_path / "data"
    assert cli_main(["simulate", "--protocols", str(protocol), "--data", str(data), "--jobs", "1",
                     "--participants", "2"]) == 0
    metas = [json.loads(p.read_text()) for p in sorted((data / "detection").glob("sub-*/ses-1/session.json"))]
    assert len(metas) == 2 and all(m["status"] == "complete" for m in metas)
    assert sum(m["n_trials_recorded"] for m in metas) < 2 * 80  # some condition stopped early
    _, results = run_power(PowerRun(protocol_path=protocol, participants=(2,), replications=1, seed=3))
    assert len(results) == 1 and results[0].n_trials < 2 * 80


def test_recover_rebuilds_a_stop_record_the_kill_left_stale(stopped_session: tuple[Path, SessionPaths],
                                                             tmp_path: Path) -> None:
    """Killed after the stopping trial was durable but before session.json said so: recover
    rebuilds ``adaptive_stop`` from the protocol, seed and log, and calls the session complete."""
    import shutil

    _, source = stopped_session
    paths = SessionPaths(tmp_path / "data", "detection", "T1", 1)
    shutil.copytree(source.directory, paths.directory)
    meta = json.loads(paths.metadata.read_text())
    recorded = meta.pop("adaptive_stop")
    meta["status"] = "running"
    paths.metadata.write_text(json.dumps(meta))
    paths.trials_parquet.unlink()
    assert cli_main(["recover", str(paths.directory)]) == 0
    meta = json.loads(paths.metadata.read_text())
    assert meta["status"] == "complete" and meta["adaptive_stop"] == recorded
