"""A window session records the window it really had (issue 31 item 6): session.json's ``display_used`` of the
run gives the framebuffer, each eye's image as presented and the rate measured from the flip timestamps, and
the BIDS export's ``StimulusPresentation`` uses them instead of the protocol's profile (1440x1600 at 90 Hz).
A real glfw window under Xvfb (subprocess)."""

from __future__ import annotations

import importlib.util
import json
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from psyop.cli import main

SCALE = 0.2
SCRIPT = textwrap.dedent(
    """
    import sys
    from pathlib import Path
    sys.path.insert(0, {helpers!r})
    from session_helpers import fast_protocol
    from psyop.protocol import load_protocol
    from psyop.schedule import compile_schedule
    from psyop.run.runner import SessionOptions, run_session
    import psyop.devices.window as window

    typed = window.GlfwWindow.poll
    def poll(self):  # a participant who always presses '2' once the prompt is up
        self.inject_key("2")
        return typed(self)
    window.GlfwWindow.poll = poll
    protocol = load_protocol(fast_protocol(Path({tmp!r}), "detection", 1, 0.03))
    outcome = run_session(protocol, compile_schedule, SessionOptions(
        participant="W1", data_root=Path({tmp!r}) / "data", clock="real", display="window",
        responses="keyboard", tracker="sim", progress=False, render="auto", window_scale={scale!r}))
    print(outcome.status)
    """
)


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs xvfb-run (Debian xvfb)")
def test_a_window_session_records_and_exports_its_real_size_and_flip_rate(tmp_path: Path) -> None:
    script = SCRIPT.format(helpers=str(Path(__file__).parents[1] / "session"), tmp=str(tmp_path), scale=SCALE)
    result = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 640x480x24", sys.executable, "-c", script],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    session = tmp_path / "data" / "detection" / "sub-W1" / "ses-1"
    meta = json.loads((session / "session.json").read_text())
    used = meta["runs"][-1]["display_used"]
    eye_px = [max(16, round(1440 * SCALE)), max(16, round(1600 * SCALE))]  # the vive_pro profile at the scale
    assert used["display"] == "window" and used["measured"] is True
    assert used["framebuffer_px"] == [max(64, eye_px[0]), max(64, eye_px[1])]  # one eye; Xvfb gives what is asked
    (eye, shown), = used["eyes"].items()
    assert [shown["width_px"], shown["height_px"]] == eye_px
    # the rate is the flips': consistent with the frame log's submit times (the flip time end_frame returns)
    submits = pd.read_parquet(session / "frames.parquet").groupby("trial")["submit_s"].diff().dropna()
    assert used["refresh_hz"] == pytest.approx(1.0 / np.median(submits[submits > 0]), rel=0.25)
    assert used["flip_intervals_measured"] > 8
    out = tmp_path / "bids"
    assert main(["export", str(tmp_path / "data"), "--bids", str(out)]) == 0
    beh = out / "sub-W1" / "ses-1" / "beh"
    for sidecar in [*beh.glob("*_events.json"), *beh.glob("*_physio.json")]:
        presentation = json.loads(sidecar.read_text())["StimulusPresentation"]
        assert presentation["ScreenResolution"] == eye_px, sidecar.name
        assert presentation["ScreenRefreshRate"] == pytest.approx(used["refresh_hz"]), sidecar.name
    if importlib.util.find_spec("bids_validator_deno") is not None:
        exe = Path(sys.executable).with_name("bids-validator-deno")
        command = [str(exe)] if exe.exists() else [sys.executable, "-c", "from bids_validator_deno import cli; cli()"]
        checked = subprocess.run([*command, str(out), "--format", "json", "--max-rows", "-1"], capture_output=True,
                                 text=True, timeout=600)
        errors = sorted({i["code"] for i in json.loads(checked.stdout)["issues"]["issues"] if i["severity"] == "error"})
        assert checked.returncode == 0 and not errors, errors
