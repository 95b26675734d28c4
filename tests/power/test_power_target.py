"""psyop power --target-power: the search over n (psyop.power.target).

The n it reports for each test and criterion is checked against power evaluated directly (a plain
``run_power`` at n - 1 and n, same seed and replications, so the same replications): the criterion
holds at n and fails at n - 1. On a shipped study (realism) and on a user protocol written here
(the QUEST+ example made small: QUEST+ runs inside the replications). An unreachable target is a
flag naming the test and the largest n tried, never a number; bad arguments are one line, exit 2.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from psyop.power.run import PowerRun, run_power
from psyop.power.target import CRITERIA, TargetSearch, bracket, search_target

ROOT = Path(__file__).resolve().parents[2]


def _check_against_direct(run: PowerRun, search: TargetSearch, table: pd.DataFrame, target: pd.DataFrame) -> int:
    """Every reported n against power evaluated directly at n - 1 and n (one plain run_power over
    all of them: a replication depends only on its seed, n and index); the number of n checked."""
    reported = {int(row[name]) for _, row in target.iterrows() for name, _, _ in CRITERIA if not pd.isna(row[name])}
    sizes = tuple(sorted(reported | {n - 1 for n in reported if n > search.min_participants}))
    direct, _ = run_power(PowerRun(run.protocol_path, sizes, run.replications, run.seed, run.effects))
    checked = 0
    for _, row in target.iterrows():
        at = direct[direct["test"] == row["test"]].set_index("participants")
        searched = table[table["test"] == row["test"]].set_index("participants")
        assert searched.loc[list(at.index)].equals(at)  # the search simulated the same replications
        for name, column, _ in CRITERIA:
            if pd.isna(row[name]):
                assert f"{row['test']}: " in row["flag"] and f"up to {search.max_participants}" in row["flag"]
                continue
            n = int(row[name])
            assert at.loc[n, column] >= search.target_power
            if n > search.min_participants:
                assert at.loc[n - 1, column] < search.target_power
            else:
                assert "smaller n not tried" in row["flag"]
            checked += 1
        if not pd.isna(row["n"]):
            assert row["power"] >= search.target_power and row["n_replications"] == run.replications
    return checked


def test_the_search_brackets_then_bisects_a_monotone_curve() -> None:
    evaluated: list[tuple[int, ...]] = []

    def curve(run: PowerRun, sizes: tuple[int, ...]) -> pd.DataFrame:
        evaluated.append(sizes)
        return pd.DataFrame([{"test": t, "participants": n, "power": min(1.0, n / d), "ci_low": min(1.0, n / d) - 0.1,
                              "ci_high": min(1.0, n / d) + 0.1, "n_replications": 10, "alpha": 0.05}
                             for t, d in (("fast", 10), ("slow", 100)) for n in sizes])

    search = TargetSearch(0.75, 2, 40)
    assert bracket(search) == [2, 4, 8, 16, 32, 40]
    table, target = search_target(PowerRun(Path("x.yaml"), (), 10), search, curve)
    fast = target.set_index("test").loc["fast"]
    assert (fast["n_ci_high"], fast["n"], fast["n_ci_low"]) == (7, 8, 9) and fast["flag"] == ""
    assert fast["power_below"] == pytest.approx(0.7)
    slow = target.set_index("test").loc["slow"]
    assert pd.isna(slow["n"]) and pd.isna(slow["n_ci_low"]) and pd.isna(slow["n_ci_high"])
    assert "slow: power estimate below 0.75 at every n tried, up to 40 (--max-participants 40)" in slow["flag"]
    assert all(len(set(s) & set(t)) == 0 for i, s in enumerate(evaluated) for t in evaluated[:i])  # each n once
    for test in ("fast", "slow"):
        sizes = list(table[table["test"] == test]["participants"])
        assert sizes == sorted(set(sizes)) and {2, 4, 8, 16, 32, 40, 7, 9} <= set(sizes)


def test_a_shipped_study_reports_n_consistent_with_power_at_n_minus_1_and_n() -> None:
    run = PowerRun(ROOT / "protocols" / "realism.yaml", (), replications=3, seed=5)
    search = TargetSearch(0.6, 2, 8)
    table, target = search_target(run, search)
    assert len(target) == 3 and _check_against_direct(run, search, table, target) >= 3
    assert target["n_ci_low"].isna().all()  # 3 replications: the lower bound never reaches 0.6
    assert target["flag"].str.contains("lower 95 % bound below 0.6 at every n tried, up to 8").all()


def test_a_user_protocol_with_quest_plus_inside(tmp_path: Path) -> None:
    text = (ROOT / "protocols" / "examples" / "detection_quest_plus.yaml").read_text()
    assert "repetitions: 40 " in text and "name: detection_quest_plus" in text
    assert "  level_column: level_D\n" in text
    path = tmp_path / "my_quest.yaml"  # an author's protocol: 8 QUEST+ trials per back distance, a threshold slope
    path.write_text(text.replace("repetitions: 40 ", "repetitions: 8 ")
                    .replace("name: detection_quest_plus", "name: my_quest")
                    .replace("  level_column: level_D\n", "  level_column: level_D\n  threshold_slope: 0.15\n"
                             "  threshold_offset_column: back_D\n"))
    run = PowerRun(path, (), replications=2, seed=2)
    search = TargetSearch(0.5, 2, 4)
    table, target = search_target(run, search)
    assert set(table["participants"]) == {2, 3, 4}  # bracket 2, 4, then bisection at 3
    assert target["n"].notna().any()  # the slope's n is found by bisection, not only flagged
    assert len(target) == 2 and _check_against_direct(run, search, table, target) >= 2


def test_cli_unreachable_target_is_a_flag_and_bad_arguments_exit_2(tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    from psyop.cli import main

    realism = str(ROOT / "protocols" / "realism.yaml")
    out = tmp_path / "power"
    assert main(["power", realism, "--target-power", "0.99", "--replications", "2", "--min-participants", "2",
                 "--max-participants", "3", "--no-progress", "--jobs", "1", "--out", str(out)]) == 0
    target = pd.read_csv(out / "target.csv")
    assert target["n_ci_low"].isna().all() and len(target) == 3 and set(target["min_participants"]) == {2}
    assert target["flag"].str.contains(r"lower 95 % bound below 0.99 at every n tried, up to 3 \(--max-par").all()
    assert sorted(pd.read_csv(out / "power.csv")["participants"].unique()) in ([2, 3], [3], [2])
    assert "target power 0.99" in capsys.readouterr().out and (out / "power.png").stat().st_size > 0
    for bad in (["--target-power", "0"], ["--target-power", "1"], ["--target-power", "1.5"],
                ["--target-power", "0.8", "--min-participants", "6", "--max-participants", "4"],
                ["--target-power", "0.8", "--min-participants", "1"],
                ["--target-power", "0.8", "--participants", "4,6"], ["--max-participants", "9"]):
        capsys.readouterr()
        assert main(["power", realism, *bad, "--no-checkpoint"]) == 2, bad
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("psyop power: error: --") and "Traceback" not in err, err
