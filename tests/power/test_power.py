"""psyop power: per-replication seeding, the table, the CLI, and the Dask path equal to the local one."""

from pathlib import Path

import pandas as pd
import pytest

from psyop.errors import UserError
from psyop.power.effects import apply_effects, parse_effects
from psyop.power.replicate import ReplicationResult, session_seed
from psyop.power.run import PowerRun, run_power
from psyop.power.study_tests import TestOutcome
from psyop.power.summary import power_table
from psyop.protocol import load_protocol

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def small_realism(tmp_path_factory) -> Path:
    """The realism protocol with 3 comparisons per pair (9 trials a session)."""
    text = (ROOT / "protocols" / "realism.yaml").read_text()
    assert "repetitions: 15 " in text
    path = tmp_path_factory.mktemp("protocols") / "realism_small.yaml"
    path.write_text(text.replace("repetitions: 15 ", "repetitions: 3 "))
    return path


def test_seeds_are_per_replication_and_stable() -> None:
    seeds = {session_seed(7, n, r, j) for n in (4, 6) for r in range(3) for j in range(6)}
    assert len(seeds) == 36
    assert session_seed(7, 6, 2, 1) == session_seed(7, 6, 2, 1)


def test_power_table_counts_and_clopper_pearson() -> None:
    results = [ReplicationResult(6, r, (TestOutcome("slope", p), TestOutcome("anova", float("nan"), "too few")), 10)
               for r, p in enumerate([0.01, 0.2, 0.04, 0.5])]
    table = power_table(results, alpha=0.05)
    slope = table[table["test"] == "slope"].iloc[0]
    assert slope["power"] == 0.5 and slope["n_significant"] == 2 and slope["n_replications"] == 4
    # Clopper-Pearson for 2 of 4, given to 7 decimals (0.0675865, 0.9324135): abs=1e-6 is that rounding with room
    assert slope["ci_low"] == pytest.approx(0.0675865, abs=1e-6) and slope["ci_high"] == pytest.approx(0.9324135, abs=1e-6)
    anova = table[table["test"] == "anova"].iloc[0]
    assert anova["power"] == 0.0 and anova["n_not_computed"] == 4
    assert list(table["test"]) == ["slope", "anova"]


def test_effects_are_validated() -> None:
    protocol = load_protocol(ROOT / "protocols" / "discrimination.yaml")
    changed = apply_effects(protocol, parse_effects(["threshold_slope=0.3", "observer.lapse=0.01"]))
    assert changed.observer.threshold_slope == 0.3 and changed.observer.lapse == 0.01
    assert protocol.observer.threshold_slope == 0.11
    with pytest.raises(UserError, match="not a parameter"):
        apply_effects(protocol, parse_effects(["slop=0.3"]))
    with pytest.raises(UserError, match="invalid"):
        apply_effects(protocol, parse_effects(["lapse=0.7"]))
    with pytest.raises(UserError, match="KEY=VALUE"):
        parse_effects(["threshold_slope"])


def test_dask_cluster_equals_local_processes(small_realism: Path) -> None:
    distributed = pytest.importorskip("distributed")
    run = PowerRun(protocol_path=small_realism, participants=(2, 3), replications=2, seed=11)
    local_table, local_results = run_power(run)
    assert len(local_results) == 4 and {r.n_trials for r in local_results} == {18, 27}
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        dask_table, dask_results = run_power(PowerRun(protocol_path=small_realism, participants=(2, 3),
                                                      replications=2, seed=11, scheduler=cluster.scheduler_address))
    assert dask_results == local_results
    pd.testing.assert_frame_equal(dask_table, local_table)
    assert set(local_table["test"]) == {"binomial: ocular over conventional", "binomial: reversed over conventional",
                                        "binomial: ocular over reversed"}
    # a different seed gives different studies
    _, other = run_power(PowerRun(protocol_path=small_realism, participants=(2,), replications=2, seed=12))
    assert [r.outcomes for r in other] != [r.outcomes for r in local_results if r.participants == 2]


def test_cli_writes_csv_and_png(small_realism: Path, tmp_path: Path) -> None:
    from psyop.cli import main

    out = tmp_path / "power"
    assert main(["power", str(small_realism), "--participants", "2,3", "--replications", "2", "--seed", "11",
                 "--out", str(out), "--jobs", "2", "--no-progress"]) == 0
    table = pd.read_csv(out / "power.csv")
    assert {"test", "participants", "power", "ci_low", "ci_high"} <= set(table.columns)
    assert sorted(table["participants"].unique()) == [2, 3]
    assert (out / "power.png").stat().st_size > 0
    assert main(["power", str(small_realism), "--effect", "nonsense=1", "--replications", "1"]) == 2
    assert main(["power", str(tmp_path / "missing.yaml")]) == 2
