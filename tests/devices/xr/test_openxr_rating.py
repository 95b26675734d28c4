"""A rating and a confidence rating answered with the controllers on a real OpenXR runtime (Monado's remote driver
emulates Valve Index controllers): ``--responses openxr``, the right stick flicked right twice from the scale's
start point (its middle), then the trigger (the remote driver's 320x240 px views fit a short prompt and a scale
without labels: the help line a default prompt adds is left out). The logged answer is the start + 2, its time is the trigger's, and
the path of highlighted points (``rating_path``, ``confidence_path``) holds the start and the two flicks, each
after the scale appeared (psyop.session.scale_picker)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pandas as pd
from monado import RemoteState, run_driven

HEAD = """
psyop_protocol: 1
study: {name: xr_scale, title: a red disc in front of a blue wall}
display: {profile: vive_pro, eye_model: gullstrand_emsley_relaxed, ipd: tracker}
eyes: stereo
scene:
  - {id: target, kind: disc, size_deg: 8, depth: {factor: level_D}, surface: {kind: solid, rgb: [1, 0, 0]}}
  - {id: wall, kind: quad, width_deg: 60, height_deg: 60, depth: {D: 0.5}, surface: {kind: solid, rgb: [0.2, 0.2, 0.6]}}
design:
  factors:
    level_D: {levels: LEVELS}
  repetitions: 1
  randomisation: {kind: full}
"""
RATING = HEAD.replace("LEVELS", "[1.0]") + """trial:
  phases:
    - {kind: interval, duration_s: 0.2}
    - {kind: response, expected_s: 2, timeout_s: 60, prompt: Rate it}
response:
  kind: rating
  stimulus: {mode: ocular}
  scale: {points: 7}
"""
CONFIDENCE = HEAD.replace("LEVELS", "[0.5, 1.0]") + """trial:
  phases:
    - {kind: interval, duration_s: 0.2}
    - {kind: interval, duration_s: 0.2}
    - {kind: response, expected_s: 2, timeout_s: 60, prompt: Which?}
response:
  kind: two_interval
  test: {mode: ocular}
  reference: {mode: conventional}
  level_factor: level_D
  confidence: {points: 4}
"""
#: the participant starts trial k CHOOSE_AFTER_S[k] after the session's folder appears (the log opens once the
#: runtime is focused and a controller is active, before the first trial, whose intervals last 0.2 s each; the next
#: trial begins when this one's trigger confirms, CONFIRM_S below), not at a fixed time from the start
CHOOSE_AFTER_S = (3.0, 12.0)
#: (start, end) from each trial's start of the choice's trigger press, of each right flick (full deflection, then rest) and of
#: the confirming trigger press: each a second long, so that a slow frame loop (llvmpipe on a loaded machine) still
#: syncs the runtime's input while it is held
CHOICE_S = (0.0, 1.0)
FLICKS_S = ((2.0, 3.0), (4.0, 5.0))
CONFIRM_S = (6.5, 7.5)


def _run(tmp_path: Path, text: str, choose: bool) -> pd.DataFrame:
    """``psyop run`` on the remote driver with, in each trial, the stick flicked right twice, then the trigger
    (after a first trigger press when ``choose``: a two_interval choice); the trials in order."""
    protocol = tmp_path / "xr_scale.yaml"
    protocol.write_text(text)
    cmd = [sys.executable, "-m", "psyop", "run", str(protocol), "--participant", "H1", "--data",
           str(tmp_path / "data"), "--display", "openxr", "--responses", "openxr", "--clock", "real", "--no-progress"]

    session = tmp_path / "data" / "xr_scale" / "sub-H1" / "ses-1"
    opened: list[float] = []

    def drive(state: RemoteState, elapsed_s: float) -> None:
        if not opened and session.is_dir():
            opened.append(elapsed_s)
        starts = [opened[0] + s for s in CHOOSE_AFTER_S if opened and elapsed_s >= opened[0] + s]
        t = elapsed_s - starts[-1] if starts else -100.0
        state.right_thumbstick_x = 1.0 if any(a <= t < b for a, b in FLICKS_S) else 0.0
        state.right_trigger = (choose and CHOICE_S[0] <= t < CHOICE_S[1]) or CONFIRM_S[0] <= t < CONFIRM_S[1]

    done = run_driven(cmd, tmp_path, RemoteState(), drive)
    assert done.returncode == 0, done.stderr[-3000:]
    trials = pd.read_parquet(tmp_path / "data" / "xr_scale" / "sub-H1" / "ses-1" / "trials.parquet")
    return trials.sort_values("trial").reset_index(drop=True)


def _check_path(path_text: str, start: int, answer_time_s: float) -> None:
    """The path: the start at 0, then one point up per flick, each after the scale appeared and before the answer,
    as far apart as the flicks and the trigger were (to half a second: the runtime's input syncs once a frame)."""
    path = json.loads(path_text)
    assert [point for _, point in path] == [start, start + 1, start + 2], path
    (t0, _), (t1, _), (t2, _) = path
    assert t0 == 0.0 and 0.0 < t1 < t2 < answer_time_s, (path, answer_time_s)
    assert abs((t2 - t1) - (FLICKS_S[1][0] - FLICKS_S[0][0])) < 0.5, path
    assert abs((answer_time_s - t2) - (CONFIRM_S[0] - FLICKS_S[1][0])) < 0.5, (path, answer_time_s)


def test_a_rating_is_picked_with_the_stick_and_confirmed_with_the_trigger(tmp_path: Path) -> None:
    trials = _run(tmp_path, RATING, choose=False)
    assert len(trials) == 1
    row = trials.iloc[0]
    assert row["response"] == "6" and row["response_value"] == 6, (row["response"], row["rating_path"])  # 4 + 2
    _check_path(row["rating_path"], 4, float(row["response_time_s"]))


def test_a_confidence_after_a_two_interval_choice_is_picked_with_the_stick(tmp_path: Path) -> None:
    trials = _run(tmp_path, CONFIDENCE, choose=True)
    assert len(trials) == 2
    for _, row in trials.iterrows():
        assert row["response"] == "2", (row["response"], row["response_time_s"])  # the right trigger: interval 2
        assert row["confidence"] == 4 and row["confidence_outcome"] == "answered", (  # start 2 (of 4) + 2
            row["confidence"], row["confidence_path"])
        _check_path(row["confidence_path"], 2, float(row["confidence_time_s"]))
