"""psyop power --precision: as many replications per n as a stated 95 % CI half-width needs.

At each n the run starts with --replications and doubles (capped at --max-replications) until every
test's Clopper-Pearson half-width is at most the precision; replication r keeps its seed, so the
result equals a plain run with that many replications. Checked with a stand-in replication (fast,
its p value a function of the replication index) and once through the CLI on a small realism study.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from psyop.errors import UserError
from psyop.power.replicate import ReplicationResult, ReplicationTask
from psyop.power.run import PowerRun, Precision, half_width, precise_power, run_power
from psyop.power.study_tests import TestOutcome

ROOT = Path(__file__).resolve().parents[2]


def _replicate(task: ReplicationTask) -> ReplicationResult:
    """Significant in 1 of 4 replications at n = 2, in every one at n = 3 (a zero-width interval)."""
    p = 0.001 if task.participants == 3 or task.replication % 4 == 0 else 0.5
    return ReplicationResult(task.participants, task.replication, (TestOutcome("t", p, 0.0, ""),), 1)


def test_replications_double_until_the_interval_is_narrow_enough() -> None:
    run = PowerRun(ROOT / "protocols" / "realism.yaml", (2, 3), 4)
    short: list[str] = []
    table, results = precise_power(run, Precision(0.1, 1000), short=short, replicate=_replicate)
    counts = table.set_index("participants")["n_replications"].to_dict()
    assert counts[2] > counts[3] > 4  # power 0.25 needs more replications than power 1 for the same width
    for n, r in counts.items():  # the smallest doubling of 4 whose interval is narrow enough
        direct, _ = run_power(PowerRun(run.protocol_path, (n,), r), replicate=_replicate)
        assert half_width(direct) <= 0.1
        if r > 4:
            fewer, _ = run_power(PowerRun(run.protocol_path, (n,), r // 2), replicate=_replicate)
            assert half_width(fewer) > 0.1
        assert table[table["participants"] == n].reset_index(drop=True).equals(direct)  # same replications
    assert sorted(r.replication for r in results if r.participants == 2) == list(range(counts[2]))
    assert not short


def test_a_cap_below_the_need_is_a_flag_not_a_silent_number() -> None:
    run = PowerRun(ROOT / "protocols" / "realism.yaml", (2,), 4)
    short: list[str] = []
    table, _ = precise_power(run, Precision(0.05, 10), short=short, replicate=_replicate)
    assert int(table["n_replications"].iloc[0]) == 10  # 4, 8, then the cap
    assert len(short) == 1 and "n = 2" in short[0] and "--max-replications 10" in short[0] \
        and "--precision 0.05" in short[0]


def test_precision_is_validated() -> None:
    for bad in (0.0, 0.5, -0.1):
        with pytest.raises(UserError, match="--precision"):
            Precision(bad, 100)
    with pytest.raises(UserError, match="--max-replications"):
        Precision(0.05, 0)


def test_cli_precision_runs_and_bad_arguments_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from psyop.cli import main

    text = (ROOT / "protocols" / "realism.yaml").read_text()
    small = tmp_path / "realism_small.yaml"
    small.write_text(text.replace("repetitions: 15 ", "repetitions: 3 "))
    out = tmp_path / "power"
    assert main(["power", str(small), "--participants", "2", "--replications", "2", "--precision", "0.3",
                 "--max-replications", "8", "--no-progress", "--jobs", "1", "--out", str(out)]) == 0
    table = pd.read_csv(out / "power.csv")
    assert set(table["n_replications"]) <= {2, 4, 8}
    r = int(table["n_replications"].max())
    assert half_width(table) <= 0.3 or (r == 8 and "flag: n = 2" in capsys.readouterr().err)
    searched = tmp_path / "searched"
    capsys.readouterr()
    assert main(["power", str(small), "--target-power", "0.99", "--replications", "2", "--precision", "0.4",
                 "--max-replications", "4", "--max-participants", "3", "--no-progress", "--jobs", "1",
                 "--out", str(searched)]) == 0
    assert "doubled up to 4 until every 95% CI half-width <= 0.4" in capsys.readouterr().out
    assert set(pd.read_csv(searched / "power.csv")["n_replications"]) <= {2, 4}
    for bad in (["--precision", "0"], ["--precision", "0.5"], ["--max-replications", "50"],
                ["--precision", "0.1", "--replications", "20", "--max-replications", "10"]):
        capsys.readouterr()
        assert main(["power", str(small), *bad, "--no-checkpoint"]) == 2, bad
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("psyop power: error: --") and "Traceback" not in err, err
