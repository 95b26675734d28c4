"""Signals to a real `psyop run` process: SIGTERM and SIGHUP end it like Ctrl-C (finalised
incomplete, one message, resumable), the count printed is the count recorded, and a second
Ctrl-C while the session is finalised still leaves a state `psyop recover` completes at once.

Every signal is a real one sent to a real child process; the tests poll with deadlines.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from psyop.cli import main as cli_main
from psyop.session.log.layout import SessionPaths
from session_helpers import fast_protocol, wait_until

SEED = 11
COMPARED = ["trial", "condition", "trial_seed", "response", "correct"]


def _real_args(protocol: Path, data: Path, participant: str) -> list[str]:
    return ["run", str(protocol), "--participant", participant, "--seed", str(SEED), "--data", str(data),
            "--clock", "real", "--no-progress", "--render", "cameras"]


def _recorded(paths: SessionPaths) -> int:
    """Trial records durably in the first segment (its size grows by one record per trial)."""
    segment = paths.trial_segment(0)
    return segment.stat().st_size if segment.exists() else 0


@pytest.mark.parametrize(("signum", "background"), [(signal.SIGTERM, False), (signal.SIGHUP, False),
                                                    (signal.SIGTERM, True)])
def test_sigterm_and_sighup_end_a_real_clock_session_like_ctrl_c(tmp_path: Path, signum: int,
                                                                 background: bool) -> None:
    """``background``: started as `psyop run ... &` from a script, with Ctrl-C ignored; a kill still ends it."""
    protocol = fast_protocol(tmp_path, "detection", 1)
    reference = tmp_path / "reference"
    assert cli_main(_real_args(protocol, reference, "S1")) == 0
    expected = pd.read_parquet(SessionPaths(reference, "detection", "S1", 1).trials_parquet)

    data = tmp_path / "data"
    paths = SessionPaths(data, "detection", "S1", 1)
    sigint = signal.SIG_IGN if background else signal.SIG_DFL
    process = subprocess.Popen([sys.executable, "-m", "psyop", *_real_args(protocol, data, "S1")],
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, sigint))
    empty = wait_until(lambda: paths.trial_segment(0).exists() and _recorded(paths), what="the segment's schema")
    wait_until(lambda: _recorded(paths) > empty or process.poll() is not None, what="a first durable trial")
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 128 + signum, stderr
    assert "Traceback" not in stderr
    lines = [line for line in stderr.splitlines() if line.startswith("psyop run:")]
    assert len(lines) == 1 and signal.Signals(signum).name in lines[0], stderr
    meta = json.loads(paths.metadata.read_text())
    assert meta["status"] == "incomplete"
    trials = pd.read_parquet(paths.trials_parquet)  # finalised without `psyop recover`
    assert f"{len(trials)}/15 recorded" in lines[0], (lines[0], len(trials))
    assert 0 < len(trials) < 15
    assert cli_main(_real_args(protocol, data, "S1")) == 0  # resumable
    final = pd.read_parquet(paths.trials_parquet)
    pd.testing.assert_frame_equal(final[COMPARED], expected[COMPARED], check_dtype=False)


_CHILD = """
import os, signal, sys
import psyop.session.log.store as store
from psyop.cli import main

where, argv = sys.argv[1], sys.argv[2:]
signal.signal(signal.SIGINT, signal.default_int_handler)  # a terminal's Ctrl-C
original_append, original_parquet = store.SessionStore.append_trial, store._write_parquet_atomic
stop_at = 1 if where == "record" else 2

def append(self, row, frames, gaze=None):  # the SIGINT arrives while this trial's record is written
    if int(row["trial"]) == stop_at:
        os.kill(os.getpid(), signal.SIGINT)
    original_append(self, row, frames, gaze)

def parquet(*args, **kwargs):  # a second Ctrl-C, between the finalised files
    os.kill(os.getpid(), signal.SIGINT)
    return original_parquet(*args, **kwargs)

store.SessionStore.append_trial = append
if where == "finalise":
    store._write_parquet_atomic = parquet
sys.exit(main(argv))
"""


def _run_interrupted(argv: list[str], where: str, tmp_path: Path) -> tuple[int, str]:
    """`psyop run argv` in a child process to which a real SIGINT comes inside ``where``."""
    done = subprocess.run([sys.executable, "-c", _CHILD, where, *argv], capture_output=True, text=True, timeout=300)
    return done.returncode, done.stderr


def test_a_sigint_during_the_record_write_counts_that_trial(tmp_path: Path, detection_small: Path) -> None:
    data = tmp_path / "data"
    argv = ["run", str(detection_small), "--participant", "I1", "--seed", str(SEED), "--data", str(data),
            "--clock", "virtual", "--no-progress", "--render", "cameras"]
    code, stderr = _run_interrupted(argv, "record", tmp_path)
    assert code == 130, stderr
    trials = pd.read_parquet(SessionPaths(data, "detection", "I1", 1).trials_parquet)
    assert trials["trial"].tolist() == [0, 1]  # trial 1's record was finished before the interrupt
    assert "2/15 recorded" in stderr and "discarded" not in stderr, stderr


def test_a_second_ctrl_c_during_finalise_leaves_a_state_recover_completes(tmp_path: Path, detection_small: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "data"
    argv = ["run", str(detection_small), "--participant", "I2", "--seed", str(SEED), "--data", str(data),
            "--clock", "virtual", "--no-progress", "--render", "cameras"]
    code, stderr = _run_interrupted(argv, "finalise", tmp_path)
    assert code == 130, stderr
    assert "Traceback" not in stderr
    paths = SessionPaths(data, "detection", "I2", 1)
    # the finalised files were written together despite the second Ctrl-C
    assert paths.trials_parquet.is_file() and paths.frames_parquet.is_file()
    assert pd.read_parquet(paths.trials_parquet)["trial"].tolist() == [0, 1, 2]
    assert json.loads(paths.metadata.read_text())["status"] == "incomplete"
    capsys.readouterr()
    assert cli_main(["recover", str(data)]) == 0  # one step, nothing to repair
    assert "3/15 trials, incomplete (resumable)" in capsys.readouterr().out
    assert cli_main(argv) == 0
    assert pd.read_parquet(paths.trials_parquet)["trial"].tolist() == list(range(15))
