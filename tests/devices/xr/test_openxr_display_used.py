"""The display that was used is the one recorded (issue 31 item 6): a headset session records the runtime's
per-eye swapchain size, fields of view and measured display rate in session.json (each run's
``display_used``), and the BIDS export describes ``StimulusPresentation`` and places gaze pixels with them,
not with the protocol's profile (``vive_pro``: 1440x1600 at 90 Hz, while Monado draws 320x240 at 20 Hz).

Against the real runtime (Monado, headless; tests/devices/xr/monado.py): the remote driver injects
asymmetric fields of view and a gaze 10 deg down; the expected values are computed here from what was
injected and from the frame log's display times, independently of psyop's code."""

from __future__ import annotations

import gzip
import importlib.util
import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from monado import RemoteDriver, RemoteState, free_port, runtime_env
from test_openxr_sessions import REPO, _protocol, _session_dir

VIVE_PRO_PX = (1440, 1600)


def _validator() -> list[str]:
    if importlib.util.find_spec("bids_validator_deno") is None:
        pytest.skip("bids-validator-deno is not installed (pip install -e '.[test]' installs it)")
    exe = Path(sys.executable).with_name("bids-validator-deno")
    return [str(exe)] if exe.exists() else [sys.executable, "-c", "from bids_validator_deno import cli; cli()"]


def _run_on_the_remote_driver(tmp_path: Path, state: RemoteState) -> None:
    port = free_port()
    cmd = [sys.executable, "-m", "psyop", "run", str(_protocol(tmp_path, interval_s=0.3, timeout_s=0.2)),
           "--participant", "H1", "--data", str(tmp_path / "data"), "--display", "openxr", "--pose", "openxr",
           "--tracker", "openxr", "--responses", "none", "--clock", "real", "--no-progress", "--render", "cameras"]
    run = subprocess.Popen(cmd, env=runtime_env(tmp_path, port), cwd=REPO, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    try:
        driver = RemoteDriver(port)
        start = time.monotonic()
        while run.poll() is None and time.monotonic() - start < 200:
            try:
                driver.send(state)
            except OSError:  # the session ended and the runtime closed the connection
                break
            time.sleep(0.02)
        _, err = run.communicate(timeout=120)
    finally:
        if run.poll() is None:
            run.kill()
    assert run.returncode == 0, err[-3000:]


def test_a_headset_session_records_and_exports_the_runtime_views_not_the_profile(tmp_path: Path) -> None:
    state = RemoteState()  # asymmetric FOVs per eye, gaze 10 deg down
    _run_on_the_remote_driver(tmp_path, state)
    session = _session_dir(tmp_path)
    meta = json.loads((session / "session.json").read_text())
    used = meta["runs"][-1]["display_used"]
    assert used["display"] == "openxr" and used["measured"] is True and used["profile"] == "vive_pro"
    sizes = meta["summary"]["display"]["swapchain_sizes_px"]  # what the swapchains were created with
    tangents = {}
    for i, eye in enumerate(("left", "right")):
        got = used["eyes"][eye]
        assert [got["width_px"], got["height_px"]] == sizes[i]
        angle_l, angle_r, angle_u, angle_d = state.fovs[i]
        tangents[eye] = [math.tan(angle_l), math.tan(angle_r), math.tan(angle_d), math.tan(angle_u)]
        np.testing.assert_allclose([got[f"tan_{s}"] for s in ("left", "right", "bottom", "top")], tangents[eye],
                                   atol=1e-6)
        assert got["fov_deg"]["left"] == pytest.approx(math.degrees(angle_l), abs=1e-4)
    assert used["fov_frames_changed"] == 0
    # the rate: 1 / the median interval of the display times the frame log recorded (the runtime's predictions)
    frames = pd.read_parquet(session / "frames.parquet")
    intervals = np.diff(np.sort(frames["display_time_s"].to_numpy()))
    assert used["refresh_hz"] == pytest.approx(1.0 / np.median(intervals[intervals > 0]), rel=1e-3)
    assert used["refresh_hz"] != pytest.approx(90.0, rel=0.05), "the test runtime paces at its own rate"

    out = tmp_path / "bids"
    done = subprocess.run([sys.executable, "-m", "psyop", "export", str(tmp_path / "data"), "--bids", str(out)],
                          cwd=REPO, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    beh = out / "sub-H1" / "ses-1" / "beh"
    stem = "sub-H1_ses-1_task-xrtiny_run-1"
    events = json.loads((beh / f"{stem}_events.json").read_text())["StimulusPresentation"]
    assert events["ScreenResolution"] == sizes[0] != list(VIVE_PRO_PX)
    assert events["ScreenRefreshRate"] == pytest.approx(used["refresh_hz"])
    ipd_m = float(meta["rig"]["ipd_m"])
    pitch = math.radians(state.gaze_pitch_deg)
    fixation = np.array([0.0, math.sin(pitch), -math.cos(pitch)])  # 1 m along the injected gaze ray
    for index, eye in enumerate(("left", "right")):
        sidecar = json.loads((beh / f"{stem}_recording-eye{index + 1}_physio.json").read_text())
        assert sidecar["RecordedEye"] == eye
        presentation = sidecar["StimulusPresentation"]
        width, height = sizes[index]
        assert presentation["ScreenResolution"] == [width, height]
        assert presentation["ScreenRefreshRate"] == pytest.approx(used["refresh_hz"])
        left, right, bottom, top = tangents[eye]
        assert presentation["ScreenSize"] == pytest.approx([right - left, top - bottom], abs=1e-6)  # at 1 m
        assert "OpenXR runtime" in sidecar["StimulusPresentationNote"]
        with gzip.open(beh / f"{stem}_recording-eye{index + 1}_physio.tsv.gz", "rt") as handle:
            table = pd.read_csv(handle, sep="\t", header=None, names=sidecar["Columns"], na_values="n/a")
        valid = table[table["valid"] == 1]
        assert len(valid) > 5
        point = fixation - np.array([(-0.5 if eye == "left" else 0.5) * ipd_m, 0.0, 0.0])
        expected_x = (point[0] / -point[2] - left) / (right - left) * width
        expected_y = (top - point[1] / -point[2]) / (top - bottom) * height
        np.testing.assert_allclose(valid["x_coordinate"], expected_x, atol=1e-3)
        np.testing.assert_allclose(valid["y_coordinate"], expected_y, atol=1e-3)
    result = subprocess.run([*_validator(), str(out), "--format", "json", "--max-rows", "-1"], capture_output=True,
                            text=True, timeout=600)
    issues = json.loads(result.stdout)["issues"]["issues"]
    errors = sorted({i["code"] for i in issues if i["severity"] == "error"})
    assert result.returncode == 0 and not errors, errors
