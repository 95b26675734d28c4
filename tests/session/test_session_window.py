"""`--display window` with keyboard responses, in a real glfw window under Xvfb (subprocess)."""

from __future__ import annotations

import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pandas as pd
import pytest

SCRIPT = textwrap.dedent(
    """
    import sys
    from pathlib import Path
    sys.path.insert(0, {helpers!r})
    from session_helpers import fast_protocol
    from psyop.protocol import load_protocol
    from psyop.schedule import compile_schedule
    from psyop.session.runner import SessionOptions, run_session
    import psyop.session.window as window

    typed = window.GlfwWindow.poll
    def poll(self):  # a participant who always presses '2' once the prompt is up
        self.inject_key("2")
        return typed(self)
    window.GlfwWindow.poll = poll
    protocol = load_protocol(fast_protocol(Path({tmp!r}), "detection", 1, 0.03))
    outcome = run_session(protocol, compile_schedule, SessionOptions(
        participant="W1", data_root=Path({tmp!r}) / "data", clock="real", display="window",
        responses="keyboard", tracker="sim", progress=False, render="auto", window_scale=0.08))
    print(outcome.status, outcome.latency["n_frames"])
    """
)


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs xvfb-run (Debian xvfb)")
def test_window_session_with_keyboard_responses(tmp_path: Path) -> None:
    script = SCRIPT.format(helpers=str(Path(__file__).parent), tmp=str(tmp_path))
    result = subprocess.run(["xvfb-run", "-a", sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    status, n_frames = result.stdout.split()[-2:]
    assert status == "complete" and int(n_frames) > 15 * 4
    session = tmp_path / "data" / "detection" / "sub-W1" / "ses-1"
    trials = pd.read_parquet(session / "trials.parquet")
    assert (trials["response"] == "2").all()
    assert (trials["correct"] == (trials["correct_interval"] == 2)).all()
    assert (trials["response_time_s"] >= 0).all()
    frames = pd.read_parquet(session / "frames.parquet")
    stimulus = frames[frames["phase"].str.startswith("interval")]
    assert stimulus["image_checked"].all() and stimulus["image_ok"].all()  # the stimulus was rendered and shown
    # flips are real and paced: outside the stimulus (no image to ray-cast on llvmpipe) consecutive
    # submits are one 90 Hz frame period apart
    frames["gap_s"] = frames.groupby("trial")["submit_s"].diff()
    gaps = frames.loc[~frames["phase"].str.startswith("interval"), "gap_s"].dropna()
    assert gaps.median() == pytest.approx(1 / 90, rel=0.5)
