"""The experimenter's keys in a session window (`psyop run --display window`) under a private Xvfb, typed as real
X key events (XTest): '2' answers, c (no gaze validation) says so once, p pauses between trials and p resumes,
logged in events.parquet, and Escape ends the session with exit 130."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import pandas as pd
import pytest

from psyop.session.log.layout import session_paths
from psyop.session.log.store import recover_tables

from session_helpers import wait_until
from test_controls_combinations import PROTOCOL
from test_window_escape import Keyboard, private_keyboard

ROOT = Path(__file__).resolve().parents[2]
XK_ESCAPE, XK_2, XK_P, XK_C = 0xFF1B, 0x32, 0x70, 0x63


@pytest.fixture
def keyboard() -> Iterator[Keyboard]:
    with private_keyboard() as keys:
        yield keys


def test_keys_in_the_session_window_pause_recalibrate_and_end_the_session(tmp_path: Path,
                                                                          keyboard: Keyboard) -> None:
    protocol = tmp_path / "pairs.yaml"
    protocol.write_text(PROTOCOL.replace("repetitions: 1", "repetitions: 2").replace("timeout_s: 0.3", "timeout_s: 30"))
    data = tmp_path / "data"
    proc = subprocess.Popen([sys.executable, "-m", "psyop", "run", str(protocol), "--participant", "W1", "--data",
                             str(data), "--display", "window", "--responses", "keyboard", "--clock", "real",
                             "--no-progress"], cwd=ROOT, env={**os.environ, "DISPLAY": keyboard.display},
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    err: list[str] = []
    reader = threading.Thread(target=lambda: err.extend(line.rstrip() for line in proc.stderr or ()), daemon=True)
    reader.start()

    def recorded() -> int:
        trials = recover_tables(session_paths(data, "pairs", "W1", 1))[0]
        return 0 if trials is None else len(trials)

    def said(text: str) -> bool:
        return any(text in line for line in err)

    def answering_until(done: Callable[[], bool]) -> Callable[[], bool]:
        def step() -> bool:
            if done():
                return True
            assert proc.poll() is None, "\n".join(err)
            keyboard.press(XK_2)
            return False
        return step

    wait_until(answering_until(lambda: recorded() >= 1), timeout_s=120, what="a trial answered in the window",
               poll_s=0.05)
    keyboard.press(XK_C)
    keyboard.press(XK_P)
    wait_until(answering_until(lambda: said("paused before trial 2 (p pressed in the session window)")),
               timeout_s=120, what="the pause", poll_s=0.05)
    assert recorded() == 2
    keyboard.press(XK_P)
    wait_until(lambda: said("resumed after"), what="the end of the pause")
    keyboard.press(XK_ESCAPE)
    rc = proc.wait(timeout=120)
    reader.join(timeout=30)
    text = "\n".join(err)
    assert rc == 130 and "Traceback" not in text, text
    assert "Escape pressed in the session window" in text and sum("c (recalibrate) does nothing" in e for e in err) == 1
    directory = session_paths(data, "pairs", "W1", 1).directory
    assert len(pd.read_parquet(directory / "trials.parquet")) == 2
    events = pd.read_parquet(directory / "events.parquet")
    assert list(events["screen"]) == ["recalibrate", "pause"] and (events["before_trial"] >= 0).all()
    assert events["ended_by"].eq("key in the session window").all() and events["duration_s"].iloc[1] > 0
