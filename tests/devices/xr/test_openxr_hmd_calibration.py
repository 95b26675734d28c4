"""Pupil Core's in-headset calibration (``pupil:...,calibrate-hmd``) in a headset session on the Monado runtime:
the targets are drawn into the runtime's swapchains once the session is FOCUSED, Capture's HMD calibration (the
stand-in of tests/devices/pupil_server.py, which fits a real mapping) succeeds, and the gaze validation that follows
measures the mapped gaze on its targets. psyop runs in a child process (the runtime lives there); the participant,
who looks at each target the drawing path shows, tells the stand-in where through Pupil Remote (``test.look_at``).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pandas as pd
from monado import runtime_env
from pupil_server import FakePupilCapture
from test_openxr_sessions import _protocol

REPO = Path(__file__).resolve().parents[3]

#: the child: the participant looks at every target 50 ms after it is shown; 0.1 s to look, then 45 frame periods
#: (the null compositor on a busy machine shows a few frames of them)
CHILD = '''
import sys
import msgpack, zmq
import psyop.run.headset as run_headset
import psyop.session.headset_calibration as calibration
import psyop.session.validation as validation
from psyop.cli import main
from psyop.optics.angles import fick_direction

req = zmq.Context().socket(zmq.REQ)
req.connect(f"tcp://127.0.0.1:{sys.argv[1]}")
real = validation.hold_target

def look_then_hold(loop, phase, start_s):
    point = [float(v) for v in phase.target_distance_m * fick_direction(*phase.target_deg)]
    req.send_multipart([b"notify.test.look_at", msgpack.packb({"subject": "test.look_at", "point_m": point,
                                                               "delay_s": 0.05})])
    req.recv()
    return real(loop, phase, start_s)

validation.hold_target = calibration.hold_target = look_then_hold
run_headset.CalibrationLayout = lambda: calibration.CalibrationLayout(settle_s=0.1, frames_per_target=45)
sys.exit(main(sys.argv[2:]))
'''


def test_pupil_calibrates_in_the_headset_on_the_runtime_and_validates(tmp_path: Path) -> None:
    path = _protocol(tmp_path)
    path.write_text(path.read_text() + "gaze_validation:\n  when: [start]\n  settle_s: 0.1\n  dwell_s: 0.2\n"
                    "  points_deg: [[0, 0], [8, 0]]\n  require: {max_mean_error_deg: 0.5, max_attempts: 1}\n")
    env = runtime_env(tmp_path)
    server = FakePupilCapture(offset_s=1000.0)
    child = tmp_path / "child.py"
    child.write_text(CHILD)
    try:
        done = subprocess.run(
            [sys.executable, str(child), str(server.port), "run", str(path), "--participant", "H1", "--data",
             str(tmp_path / "data"), "--display", "openxr", "--pose", "openxr", "--clock", "real", "--responses",
             "none", "--no-progress", "--tracker", f"pupil:127.0.0.1:{server.port},calibrate-hmd"],
            env=env, cwd=REPO, capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)
    finally:
        server.stop()
    assert done.returncode == 0, done.stderr[-3000:]
    session = tmp_path / "data" / "xr_tiny" / "sub-H1" / "ses-1"
    meta = json.loads((session / "session.json").read_text())
    assert meta["summary"]["display"]["display"] == "openxr"
    record = meta["runs"][0]["headset_calibrations"]
    assert [r["status"] for r in record] == ["successful"], record
    assert all(r["n_frames"] >= 1 for r in record[0]["references"]) and server.hmd_fit is not None
    validation = pd.read_parquet(session / "validation.parquet")
    overall = validation[validation["point"] == -1].iloc[0]
    assert bool(overall["passed"]) and overall["mean_error_deg"] < 0.2
