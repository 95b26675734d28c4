"""``--experimenter-window`` on a real OpenXR runtime (Monado, headless) under Xvfb: the mirror shows the
participant's (left) eye, the status line follows the session, and ``--responses keyboard`` reads the
window's keys (issue 45, items 1 and 2)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import textwrap

import pandas as pd
import pytest

from monado import runtime_env
from test_openxr_sessions import REPO, _protocol, _session_dir

#: psyop run, with a participant who types '2' into the experimenter window whenever it is polled; the window's
#: framebuffer is read back at each mirror update (the test's cost, not the window's), and every status kept
SCRIPT = textwrap.dedent(
    """
    import json, sys
    from pathlib import Path
    import numpy as np
    import psyop.devices.experimenter as ex

    seen = {"non_grey_share": None, "statuses": []}
    typed = ex.ExperimenterWindow.poll

    def poll(self):
        self.inject_key("2")
        return typed(self)

    shown = ex.ExperimenterWindow.show_mirror

    def show_mirror(self, pixels):
        shown(self, pixels)
        if pixels is not None:  # the stimulus frames' phase depends on the machine's speed: every update is read
            mirror = self.screen_pixels()[: self.mirror_px[1]].astype(int)
            non_grey = float((np.abs(mirror - 128).max(axis=2) > 8).mean())  # not the cleared grey
            red = float(((mirror[..., 0] > 150) & (mirror[..., 1] < 80)).mean())  # the red disc
            seen["non_grey_share"] = max(non_grey, seen["non_grey_share"] or 0.0)
            seen["red_share"] = max(red, seen.get("red_share", 0.0))
        seen["statuses"].append(self.status_line)

    ex.ExperimenterWindow.poll, ex.ExperimenterWindow.show_mirror = poll, show_mirror
    from psyop.cli import main

    rc = main(sys.argv[2:])
    Path(sys.argv[1]).write_text(json.dumps(seen))
    sys.exit(rc)
    """
)


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs xvfb-run (Debian xvfb)")
def test_a_headset_session_answered_in_the_experimenter_window_mirrors_the_eye_and_shows_the_status(tmp_path):
    protocol = _protocol(tmp_path, timeout_s=5.0)
    seen_file = tmp_path / "seen.json"
    argv = ["xvfb-run", "-a", "-s", "-screen 0 640x480x24", sys.executable, "-c", SCRIPT, str(seen_file), "run",
            str(protocol), "--participant", "H1", "--data", str(tmp_path / "data"), "--display", "openxr", "--pose",
            "openxr", "--clock", "real", "--responses", "keyboard", "--experimenter-window", "--no-progress"]
    done = subprocess.run(argv, env=runtime_env(tmp_path), cwd=REPO, capture_output=True, text=True, timeout=240,
                          stdin=subprocess.DEVNULL)
    assert done.returncode == 0, done.stderr[-3000:]
    trials = pd.read_parquet(_session_dir(tmp_path) / "trials.parquet")
    assert list(trials["response"]) == ["2", "2"]  # typed into the experimenter window
    assert (trials["correct"] == (trials["correct_interval"] == 2)).all() and (trials["response_time_s"] >= 0).all()
    seen = json.loads(seen_file.read_text())
    # the mirror showed the stimulus: the blue wall and the red disc, not the swapchain's cleared grey
    assert seen["non_grey_share"] > 0.3 and seen["red_share"] > 0.001, seen
    statuses = seen["statuses"]
    assert any(s.startswith("trial 1 of 2 | condition level_D=") for s in statuses), statuses
    last = statuses[-1]
    assert last.startswith("trial 2 of 2") and "last answer 2" in last and "recorded 1" in last, last
    assert re.search(r"dropped frames \d+ \| gaze valid \d+%$", last), last  # the simulated tracker blinks
    meta = json.loads((_session_dir(tmp_path) / "session.json").read_text())
    assert meta["status"] == "complete" and meta["summary"]["display"]["display"] == "openxr"
    window = meta["summary"]["display"]["experimenter_window"]
    assert window["mirror_updates"] >= 2 and window["mirror_px"][0] == 320
    assert window["readback_and_present_after_submit"]["median_ms"] is not None  # its cost, measured per update
