"""The protocol's ``timing:`` rule (issue 31 item 3): validated like every section (located errors, exit 2),
and applied: ``flag`` keeps a trial whose intervals dropped too many frames with ``timing_ok`` false,
``rerun`` discards it and runs it again at the end of its block, saying which and why."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

import psyop.session.loop as loop
import psyop.run.runner as runner
from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.run.runner import SessionOptions, run_session

from timing_helpers import SlowRenderer, check_session, timing_protocol

ROOT = Path(__file__).resolve().parents[2]


def _run(tmp_path: Path, timing: str, clock: str = "real") -> Path:
    outcome = run_session(load_protocol(timing_protocol(tmp_path, timing)), compile_schedule, SessionOptions(
        participant="R1", data_root=tmp_path / "data", clock=clock, display="headless", progress=False,
        render="cameras", every_frame=True))
    assert outcome.status == "complete", outcome.message
    return tmp_path / "data" / "detection" / "sub-R1" / "ses-1"


@pytest.mark.parametrize(("text", "says"), [
    ("timing: {max_dropped_frames: -1, on_violation: flag}\n", "must be at least 0"),
    ("timing: {max_dropped_frames: 2, on_violation: ignore}\n", "rerun"),
    ("timing: {max_dropped_frames: 2}\n", "on_violation"),
    ("timing: {max_dropped_frames: 2, on_violation: rerun, max_dropped: 3}\n", "max_dropped"),
    ("timing: {max_dropped_frames: true, on_violation: flag}\n", "boolean"),
    ("timing: {max_dropped_frames: 2, on_violation: rerun, max_rerun_share: 1.5}\n", "must be at most 1"),
    ("timing: {max_dropped_frames: 2, on_violation: rerun, max_rerun_share: 0}\n", "greater than 0"),
    ("timing: {max_dropped_frames: 2, on_violation: flag, max_rerun_share: 0.2}\n", "use it with on_violation: rerun"),
])
def test_a_bad_timing_section_is_one_located_line_exit_2(tmp_path: Path, text: str, says: str) -> None:
    path = timing_protocol(tmp_path, text)
    line = len(path.read_text().splitlines())  # the section is the file's last line
    result = subprocess.run([sys.executable, "-m", "psyop", "validate", str(path)], capture_output=True, text=True,
                            cwd=ROOT, timeout=120)
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr
    assert f"{path.name}:{line}" in result.stderr and says in result.stderr, result.stderr


def test_a_timing_rule_on_the_virtual_clock_flags_nothing(tmp_path: Path) -> None:
    session = _run(tmp_path, "timing: {max_dropped_frames: 0, on_violation: rerun}\n", clock="virtual")
    trials = pd.read_parquet(session / "trials.parquet")
    assert trials["timing_ok"].tolist() == [True] * len(trials)
    assert "timing_reruns" not in json.loads((session / "session.json").read_text())


@pytest.mark.slow
def test_flag_keeps_the_trial_with_timing_ok_false(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(runner, "CameraRenderer", SlowRenderer)
    SlowRenderer.calls = []
    session = _run(tmp_path, "timing: {max_dropped_frames: 0, on_violation: flag}\n")
    check_session(session, SlowRenderer.calls)
    trials = pd.read_parquet(session / "trials.parquet")
    dropped = trials["interval1_dropped_frames"] + trials["interval2_dropped_frames"]
    assert dropped.gt(0).any()
    assert trials["timing_ok"].tolist() == dropped.eq(0).tolist()
    assert "timing_reruns" not in json.loads((session / "session.json").read_text())


@pytest.mark.slow
def test_rerun_runs_the_trial_again_at_the_end_of_its_block_and_says_why(tmp_path: Path,
                                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(runner, "CameraRenderer", SlowRenderer)
    SlowRenderer.calls = []
    events: list[tuple[str, int, str]] = []
    emit = loop.TrialLoop._emit

    def recording(self, kind, row, t_s, value="", duration_s=0.0):  # type: ignore[no-untyped-def]
        events.append((kind, int(row["trial"]), value))
        return emit(self, kind, row, t_s, value, duration_s)

    monkeypatch.setattr(loop.TrialLoop, "_emit", recording)
    session = _run(tmp_path, "timing: {max_dropped_frames: 0, on_violation: rerun, max_reruns: 1}\n")
    meta = json.loads((session / "session.json").read_text())
    trials = pd.read_parquet(session / "trials.parquet").sort_values("trial_start_s")
    reruns = meta["timing_reruns"]
    assert reruns, "every third frame takes 2.3 periods: some interval must have dropped a frame"
    rerun_trials = [r["trial"] for r in reruns]
    assert len(set(rerun_trials)) == len(rerun_trials)  # max_reruns: 1
    for r in reruns:
        assert r["dropped_frames"] > 0 and "timing.max_dropped_frames = 0" in r["reason"]
    # one record per trial; a re-run trial was run after every first attempt of its block (one block here)
    assert sorted(trials["trial"]) == list(range(len(trials)))
    starts = trials.set_index("trial")["trial_start_s"]
    assert all(starts[r["trial"]] > r["at_s"] for r in reruns)  # the kept attempt came after the discarded one
    # the kept attempt after the last allowed rerun is flagged when it dropped too
    kept = trials.set_index("trial")
    for trial in rerun_trials:
        dropped = kept.loc[trial, "interval1_dropped_frames"] + kept.loc[trial, "interval2_dropped_frames"]
        assert kept.loc[trial, "timing_ok"] == (dropped == 0)
    told = [(t, v) for kind, t, v in events if kind == "timing_rerun"]
    assert [t for t, _ in told] == rerun_trials and all("dropped" in v for _, v in told)
    order = [t for kind, t, _ in events if kind == "trial_start"]
    assert len(order) == len(trials) + len(reruns)
    for trial in rerun_trials:  # the second start of a re-run trial comes after every other trial's first
        assert order.index(trial, order.index(trial) + 1) >= len(trials)
