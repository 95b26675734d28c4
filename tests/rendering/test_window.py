"""A real window under Xvfb: frames reach the screen, timestamps are recorded, drops counted."""

from __future__ import annotations

import os
import shutil
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from psyop.rendering.window import count_dropped_frames

REPO_ROOT = Path(__file__).resolve().parents[2]
PROBE = Path(__file__).resolve().with_name("window_probe.py")


@pytest.fixture(scope="module")
def x_display():
    """$DISPLAY if set, else a private Xvfb server for this module."""
    if os.environ.get("DISPLAY"):
        yield os.environ["DISPLAY"]
        return
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        pytest.skip("Xvfb is not installed (apt-get install xvfb xauth; `make test` installs it)")
    read_fd, write_fd = os.pipe()
    proc = subprocess.Popen([xvfb, "-displayfd", str(write_fd), "-screen", "0", "640x480x24", "-nolisten", "tcp"],
                            pass_fds=(write_fd,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(write_fd)
    with os.fdopen(read_fd) as f:
        number = f.readline().strip()
    if not number:
        proc.kill()
        pytest.skip("Xvfb did not start")
    yield f":{number}"
    proc.terminate()
    proc.wait(timeout=10)


def test_count_dropped_frames():
    stamps = np.array([0.0, 1.0, 2.0, 4.0, 5.0, 8.1]) / 90.0
    assert count_dropped_frames(stamps, 1 / 90.0) == (3, 2)


def test_window_presents_frames_and_logs_timing(x_display):
    env = dict(os.environ, DISPLAY=x_display)
    proc = subprocess.run([sys.executable, str(PROBE)], env=env, cwd=REPO_ROOT,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    if "unavailable" in result:
        pytest.skip(f"no window could be opened on {x_display}: {result['unavailable']}")
    refresh_s = result["refresh_s"]
    stall = result["stall_frame"]
    stamps = np.array(result["present_s"])
    slots = np.array(result["slot_start_s"])
    assert stamps.shape == (20,) and np.all(np.diff(stamps) > 0)
    # paced by the clock: no frame starts before its slot, slots are whole refresh intervals apart
    assert np.all(stamps >= slots)
    steps = np.diff(slots) / refresh_s
    assert np.allclose(steps, np.round(steps), atol=1e-6) and np.all(np.round(steps) >= 1)
    assert (result["dropped"], result["late"]) == count_dropped_frames(stamps, refresh_s)
    assert stamps[stall] - stamps[stall - 1] >= 4.5 * refresh_s
    assert result["dropped"] >= 4 and result["late"] >= 1
    # the frame really reached the window: green disc centre on a blue background
    assert result["centre_rgb"][1] > 200 and result["corner_rgb"][2] > 100 and result["corner_rgb"][1] < 20
