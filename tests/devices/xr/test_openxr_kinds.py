"""Controller answers of the new response kinds on a real OpenXR runtime (Monado's remote driver, as
tests/devices/xr/test_openxr_sessions.py): the right controller's select button answers "no" in a yes_no study
and "2" in a 2-AFC n_afc study, each trial's answer scored against its schedule (an n_afc with more alternatives is
answered with the stick: tests/devices/xr/test_openxr_choice_stick.py)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from monado import RemoteState, run_driven


HEAD = """
psyop_protocol: 1
study: {name: xr_kind, title: a red disc in front of a blue wall}
display: {profile: vive_pro, eye_model: gullstrand_emsley_relaxed, ipd: tracker}
eyes: stereo
scene:
  - {id: target, kind: disc, size_deg: 8, depth: {D: 1}, surface: {kind: solid, rgb: [1, 0, 0]}}
  - {id: wall, kind: quad, width_deg: 60, height_deg: 60, depth: {D: 0.5}, surface: {kind: solid, rgb: [0.2, 0.2, 0.6]}}
design:
  factors:
    level_D: {levels: [0, 1]}
  repetitions: 1
  randomisation: {kind: full}
"""
YES_NO = """trial:
  phases:
    - {kind: interval, duration_s: 0.4}
    - {kind: response, expected_s: 0.2, timeout_s: 5}
response:
  kind: yes_no
  signal: {mode: ocular}
  noise: {mode: conventional}
  level_factor: level_D
"""
TWO_AFC = """trial:
  phases:
    - {kind: interval, duration_s: 0.3}
    - {kind: interval, duration_s: 0.3}
    - {kind: response, expected_s: 0.2, timeout_s: 5}
response:
  kind: n_afc
  n: 2
  target: {mode: ocular}
  reference: {mode: conventional}
  level_factor: level_D
"""


def _run_pressing_right(tmp_path: Path, protocol: Path) -> subprocess.CompletedProcess:
    """``psyop run`` on the remote driver, the right trigger pressed every 0.3 s until the session ends."""
    cmd = [sys.executable, "-m", "psyop", "run", str(protocol), "--participant", "H1", "--data",
           str(tmp_path / "data"), "--display", "openxr", "--pose", "openxr:right", "--responses", "openxr",
           "--clock", "real", "--no-progress"]

    def press(state: RemoteState, elapsed_s: float) -> None:
        state.right_trigger = int(elapsed_s / 0.15) % 2 == 1

    return run_driven(cmd, tmp_path, RemoteState(), press)


@pytest.mark.parametrize(("tail", "answer", "correct"), [
    (YES_NO, "no", lambda t: ~t["signal"].astype(bool)),
    (TWO_AFC, "2", lambda t: t["correct_interval"] == 2),
])
def test_the_right_controller_answers_the_kind(tmp_path: Path, tail: str, answer: str, correct) -> None:
    protocol = tmp_path / "xr_kind.yaml"
    protocol.write_text(HEAD + tail)
    done = _run_pressing_right(tmp_path, protocol)
    assert done.returncode == 0, done.stderr[-3000:]
    trials = pd.read_parquet(tmp_path / "data" / "xr_kind" / "sub-H1" / "ses-1" / "trials.parquet")
    assert len(trials) == 2 and (trials["response"] == answer).all(), trials[["response"]]
    assert (trials["correct"] == correct(trials)).all() and (trials["response_time_s"] > 0).all()

