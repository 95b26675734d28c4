"""psyop power's replications record into memory (psyop.power.memory_log) instead of durable
session logs: the analysis must see the same table and the power table must be the same bytes.

For every shipped study and the adaptive example, on identical seeds, the trial table of the
in-memory path equals load_dataset's table read back from the full path's finalised parquet files
(every column, every dtype, every value), and power.csv's text is identical. The in-memory path
writes nothing: no scratch folder, nothing in the working directory.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pandas as pd
import pytest

from psyop.power.memory_log import MemoryLog
from psyop.power.replicate import (
    ReplicationResult,
    ReplicationTask,
    replication_trials,
    replication_trials_durable,
    run_replication_durable,
)
from psyop.power.run import PowerRun, run_power
from psyop.power.study_tests import study_tests
from psyop.power.summary import power_table

pytestmark = pytest.mark.cross_cpu

ROOT = Path(__file__).resolve().parents[2]
PROTOCOLS = [ROOT / "protocols" / f"{name}.yaml" for name in
             ("detection", "discrimination", "ordinal", "egocentric", "realism")]
PROTOCOLS.append(ROOT / "protocols" / "examples" / "detection_quest_plus.yaml")


def _task(path: Path, participants: int = 2, replication: int = 0, seed: int = 3) -> ReplicationTask:
    return ReplicationTask(path.read_text(), str(path), (), participants, replication, seed)


@pytest.mark.parametrize("path", PROTOCOLS, ids=lambda p: p.stem)
def test_the_in_memory_path_hands_the_analysis_the_table_load_dataset_reads_and_power_csv_is_identical(
        path: Path) -> None:
    task = _task(path)
    protocol, memory = replication_trials(task)
    _, durable = replication_trials_durable(task)
    assert len(memory) > 0
    pd.testing.assert_frame_equal(memory, durable, check_exact=True)
    assert list(memory.dtypes) == list(durable.dtypes)
    results = [ReplicationResult(2, 0, tuple(study_tests(protocol, t)), len(t)) for t in (memory, durable)]
    assert repr(results[0]) == repr(results[1])  # equal, NaN p values included (an untestable joint test)
    memory_csv, durable_csv = (power_table([r]).to_csv(index=False) for r in results)
    assert memory_csv == durable_csv


def test_run_power_on_both_paths_writes_the_same_power_csv(tmp_path: Path) -> None:
    text = (ROOT / "protocols" / "realism.yaml").read_text().replace("repetitions: 15 ", "repetitions: 3 ")
    protocol = tmp_path / "realism_small.yaml"
    protocol.write_text(text)
    run = PowerRun(protocol_path=protocol, participants=(2, 3), replications=2, seed=8)
    fast, _ = run_power(run)
    full, _ = run_power(run, replicate=run_replication_durable)
    assert fast.to_csv(index=False) == full.to_csv(index=False)


def test_an_in_memory_replication_writes_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Nothing in the working folder, nothing in a temporary folder of its own (a private one: the machine's
    /tmp is shared with the other test workers, whose durable replications make psyop-power-* folders)."""
    work, scratch = tmp_path / "work", tmp_path / "scratch"
    work.mkdir()
    scratch.mkdir()
    monkeypatch.chdir(work)
    monkeypatch.setenv("TMPDIR", str(scratch))
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    replication_trials(_task(ROOT / "protocols" / "discrimination.yaml"))
    assert os.listdir(work) == []
    assert os.listdir(scratch) == []


#: a trial rule that excludes every trial whose requested gaze sample was lost (a blink at the recalibration)
QUALITY = """
quality:
  trials:
    - measure: data_loss_share
      max: 0.0
      reason: gaze lost during the trial (test rule)
"""


def test_quality_rules_exclude_the_same_trials_on_both_paths(tmp_path: Path) -> None:
    """issue 27: a power analysis of a protocol with quality: rules analyses the included data, as
    load_dataset gives it to the real analysis (the rules measured from the raw gaze kept in memory)."""
    path = tmp_path / "detection_quality.yaml"
    path.write_text((ROOT / "protocols" / "detection.yaml").read_text() + QUALITY)
    task = _task(path)
    protocol, memory = replication_trials(task)
    _, durable = replication_trials_durable(task)
    assert protocol.quality is not None and durable.attrs["n_quality_excluded"] > 0  # the rule excludes trials
    _, unruled = replication_trials(_task(ROOT / "protocols" / "detection.yaml"))
    assert len(memory) == len(unruled) - durable.attrs["n_quality_excluded"]
    pd.testing.assert_frame_equal(memory, durable, check_exact=True)
    results = [ReplicationResult(2, 0, tuple(study_tests(protocol, t)), len(t)) for t in (memory, durable)]
    assert repr(results[0]) == repr(results[1])
    assert power_table([results[0]]).to_csv(index=False) == power_table([results[1]]).to_csv(index=False)


@pytest.mark.parametrize("trials", [[0, 1, 2, 5], [2, 0, 1], [0, 1, 1, 3], [3, 1, 3, 0], []],
                         ids=["ascending", "out-of-order", "repeated", "both", "empty"])
def test_finalise_keeps_each_trials_first_record_in_trial_order(trials):
    """A timing re-run records a trial after later ones: finalise gives what drop_duplicates (first) and a
    stable sort by trial give, with a RangeIndex, whether the records came in order (nothing to do) or not."""
    import pyarrow as pa

    from psyop.power.memory_log import MemoryLog
    from psyop.session.log.layout import SessionPaths

    schema = pa.schema([("trial", pa.int64()), ("response", pa.string()), ("level_D", pa.float64())])
    log = MemoryLog(SessionPaths(Path("nowhere"), "study", "S01", 1), schema)
    for k, trial in enumerate(trials):
        log.append_trial({"trial": trial, "response": f"r{k}", "level_D": 0.25 * k}, None)
    log.finalise(status="complete")
    got = log.trials
    table = pa.Table.from_pydict({"trial": trials, "response": [f"r{k}" for k in range(len(trials))],
                                  "level_D": [0.25 * k for k in range(len(trials))]}, schema=schema).to_pandas()
    want = table.drop_duplicates(subset="trial", keep="first").sort_values("trial", kind="stable").reset_index(drop=True)
    pd.testing.assert_frame_equal(got, want, check_index_type=True)
    assert isinstance(got.index, pd.RangeIndex)


def _log(rows: list[dict], schema) -> MemoryLog:
    from psyop.session.log.layout import SessionPaths

    log = MemoryLog(SessionPaths(Path("nowhere"), "study", f"S{len(rows):02d}", 1), schema)
    for row in rows:
        log.append_trial(row, None)
    log.finalise(status="complete")
    return log


def test_sessions_converted_at_once_equal_each_converted_then_concatenated():
    """concatenated_trials converts the sessions' arrow tables at once: the frame pandas' concat of each
    session's own conversion gives, where the sessions differ in which columns hold nulls (an int column
    float64 in one and int64 in the other, a bool column object in one), in strings, lists and all-null
    columns; and the per-session path where a session had a re-run trial."""
    import pyarrow as pa

    from psyop.power.memory_log import concatenated_trials

    schema = pa.schema([("trial", pa.int64()), ("n", pa.int64()), ("ok", pa.bool_()), ("s", pa.string()),
                        ("x", pa.float64()), ("hand", pa.list_(pa.float64())), ("none", pa.float64())])
    a = [{"trial": 0, "n": 1, "ok": True, "s": "a", "x": 0.5, "hand": [1.0, 2.0]},
         {"trial": 1, "n": None, "ok": None, "s": None, "x": None, "hand": None}]
    b = [{"trial": 0, "n": 3, "ok": False, "s": "b", "x": 1.5, "hand": []},
         {"trial": 2, "n": 4, "ok": True, "s": "c", "x": float("nan"), "hand": [3.0]}]
    rerun = [{"trial": 1, "n": 5, "ok": True, "s": "d", "x": 2.0}, {"trial": 0, "n": 6, "ok": False, "s": "e", "x": 3.0}]
    for sessions in ([a, b], [b, a], [b, b], [a], [a, rerun, b]):
        logs = [_log(rows, schema) for rows in sessions]
        want = pd.concat([log.arrow_trials.to_pandas() if log.arrow_trials is not None else log.trials
                          for log in logs], ignore_index=True)
        got = concatenated_trials(logs)
        pd.testing.assert_frame_equal(got, want, check_index_type=True)
        assert [str(t) for t in got.dtypes] == [str(t) for t in want.dtypes]


@pytest.mark.parametrize("shape", ["validated", "words", "mixed"])
def test_protocols_psyop_does_not_ship_run_on_both_paths_alike(tmp_path: Path, shape: str) -> None:
    """issue 41: gaze validation with quality: rules (the validation kept in memory, never in a file under the
    replication's scratch name: it failed with "validation-000.psylog: No such file or directory"), a condition
    factor of words, and numbers and words crossed: the in-memory path gives the durable path's table and tests."""
    from tests import unshipped_protocols

    kwargs = {"validation_max_deg": 0.6} if shape == "validated" else {}  # excludes one of the two
    task = _task(unshipped_protocols.write(tmp_path, shape, **kwargs))
    protocol, memory = replication_trials(task)
    _, durable = replication_trials_durable(task)
    pd.testing.assert_frame_equal(memory, durable, check_exact=True)
    tests = study_tests(protocol, memory)
    results = [ReplicationResult(2, 0, tuple(study_tests(protocol, t)), len(t)) for t in (memory, durable)]
    assert repr(results[0]) == repr(results[1])
    assert power_table([results[0]]).to_csv(index=False) == power_table([results[1]]).to_csv(index=False)
    names = [t.test for t in tests]
    if shape == "mixed":  # thresholds over the crossed cells; no slope over words
        assert names == ["rm-ANOVA: threshold ~ the crossed cells of back_D x mode"]
    else:
        assert names == ["rm-ANOVA: threshold ~ mode"]
    if shape == "validated":  # the participant rule on the validation's error was measured and applied
        assert durable.attrs["n_quality_excluded"] > 0 and memory["participant"].nunique() == 1


def test_psyop_power_runs_on_a_protocol_with_gaze_validation_and_quality_rules(tmp_path: Path) -> None:
    """The command that failed with a path inside its own scratch folder (issue 41) now reports power."""
    from psyop.cli import main as cli_main
    from tests import unshipped_protocols

    protocol = unshipped_protocols.write(tmp_path, "validated")
    out = tmp_path / "power"
    assert cli_main(["power", str(protocol), "--participants", "2", "--replications", "1", "--jobs", "1",
                     "--no-progress", "--no-checkpoint", "--out", str(out)]) == 0
    table = pd.read_csv(out / "power.csv")
    assert list(table["test"]) == ["rm-ANOVA: threshold ~ mode"]
