"""Reruns in the open (issue 45 item 4): a timing rule the display cannot keep never loops silently. Each
rerun prints one line; ``timing.max_rerun_share`` stops the run within its limit with one line naming the rule
and what to change (exit 3, resumable, the recorded trials intact); the summary counts the reruns.

The display is a stand-in for a slow one: the headless display on the virtual clock, reporting display
periods skipped before every frame of the trials the test makes slow (a rule of ``max_dropped_frames: 0``
is then never met by them)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pandas as pd
import pytest

import psyop.session.frames as frames
import psyop.session.loop as loop
from psyop.protocol import load_protocol
from psyop.run.runner import SessionOptions, print_outcome, run_session
from psyop.schedule import compile_schedule
from psyop.session.loop import SessionOutcome

from timing_helpers import timing_protocol

SLOW: set[int] = set()  # the trials whose frames the stand-in display drops (every frame, every attempt)


class SlowDisplay(frames.HeadlessDisplay):
    """The headless display, skipping two display periods before each frame of a slow trial."""

    trial = -1

    def begin_frame(self, not_before_s: float) -> frames.FrameRequest:
        request = super().begin_frame(not_before_s)
        return dataclasses.replace(request, missed_frames=2) if SlowDisplay.trial in SLOW else request


@pytest.fixture
def slow_display(monkeypatch: pytest.MonkeyPatch) -> set[int]:
    """The stand-in display in place of the headless one; the set of slow trials, to fill."""
    run_trial = loop.TrialLoop.run_trial

    def tracked(self: loop.TrialLoop, row: dict) -> tuple:  # type: ignore[type-arg]
        SlowDisplay.trial = int(row["trial"])
        return run_trial(self, row)

    monkeypatch.setattr(loop.TrialLoop, "run_trial", tracked)
    monkeypatch.setattr(frames, "HeadlessDisplay", SlowDisplay)
    SLOW.clear()
    return SLOW


def _run(protocol: Path, data: Path, capsys: pytest.CaptureFixture[str]) -> tuple[SessionOutcome, list[str]]:
    outcome = run_session(load_protocol(protocol), compile_schedule, SessionOptions(
        participant="T1", data_root=data, clock="virtual", display="headless", progress=False, render="cameras",
        every_frame=True))
    print_outcome(outcome)
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return outcome, err.splitlines()


def test_a_rule_the_display_never_meets_stops_the_session_within_its_share(
        tmp_path: Path, slow_display: set[int], capsys: pytest.CaptureFixture[str]) -> None:
    protocol = timing_protocol(tmp_path, "timing: {max_dropped_frames: 0, on_violation: rerun, max_reruns: 5, "
                                         "max_rerun_share: 0.25}\n")
    n = len(compile_schedule(load_protocol(protocol), 0))
    limit = int(0.25 * n)
    slow_display.update(range(2, n))  # the display slows down after two trials, for good
    outcome, err = _run(protocol, tmp_path / "data", capsys)
    assert outcome.status == "timing_stopped" and outcome.exit_code == 3, outcome.message
    assert outcome.n_recorded == 2
    session = tmp_path / "data" / "detection" / "sub-T1" / "ses-1"
    meta = json.loads((session / "session.json").read_text())
    assert len(meta["timing_reruns"]) == limit  # stopped at the attempt one past the limit, never looping
    assert meta["timing_stop"]["limit"] == limit and meta["timing_stop"]["dropped_frames"] > 0
    assert meta["status"] == "incomplete" and meta["summary"]["timing_reruns"] == limit
    # each rerun printed its reason (one line); then one end line names the rule and what to change
    reruns = [line for line in err if "discarded, to be run again" in line]
    assert len(reruns) == limit and all("timing.max_dropped_frames = 0" in line for line in reruns)
    end = [line for line in err if line.startswith("psyop run: timing_stopped:")]
    assert len(end) == 1 and "timing.max_rerun_share 0.25" in end[0]
    assert "make it drop fewer frames" in end[0] and "run the same command to resume" in end[0]
    assert f"{limit} attempt(s) discarded by the timing rule" in end[0]
    # the recorded trials are intact, the stopped attempt discarded (not recorded)
    trials = pd.read_parquet(session / "trials.parquet")
    assert sorted(trials["trial"]) == [0, 1] and trials["timing_ok"].all()
    kept = trials.copy()
    # resumed on a display that keeps up: the session completes, the first run's trials and reruns kept
    slow_display.clear()
    outcome, err = _run(protocol, tmp_path / "data", capsys)
    assert outcome.status == "complete", outcome.message
    trials = pd.read_parquet(session / "trials.parquet")
    assert sorted(trials["trial"]) == list(range(n))
    pd.testing.assert_frame_equal(trials[trials["trial"] < 2].reset_index(drop=True)[kept.columns],
                                  kept.reset_index(drop=True), check_dtype=False)
    meta = json.loads((session / "session.json").read_text())
    assert [r["run"] for r in meta["timing_reruns"]] == [0] * limit  # the first run's, not overwritten
    assert meta["summary"]["timing_reruns"] == 0


def test_each_rerun_prints_and_the_summary_counts_them(tmp_path: Path, slow_display: set[int],
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    protocol = timing_protocol(tmp_path, "timing: {max_dropped_frames: 0, on_violation: rerun, max_reruns: 2}\n")
    slow_display.add(1)  # trial 1 never keeps the rule: run 3 times, the last attempt kept, flagged
    outcome, err = _run(protocol, tmp_path / "data", capsys)
    assert outcome.status == "complete", outcome.message
    reruns = [line for line in err if "trial 1 discarded, to be run again" in line]
    assert [("rerun 1 of at most 2" in reruns[0]), ("rerun 2 of at most 2" in reruns[1])] == [True, True]
    assert len(reruns) == 2
    end = [line for line in err if line.startswith("psyop run: complete:")]
    assert len(end) == 1 and "2 attempt(s) discarded by the timing rule" in end[0]
    session = tmp_path / "data" / "detection" / "sub-T1" / "ses-1"
    meta = json.loads((session / "session.json").read_text())
    assert meta["summary"]["timing_reruns"] == 2 and "2 attempt(s)" in meta["summary"]["message"]
    trials = pd.read_parquet(session / "trials.parquet").set_index("trial")
    assert not trials.loc[1, "timing_ok"] and trials.drop(index=1)["timing_ok"].all()
