"""Meshes on the OpenXR display (issue 26), against the Monado runtime (tests/devices/xr/monado.py; skipped
with the reason without one): a stereo scene of two glTF nodes (assets/teaser.glb's candle and bottle) and an
analytic wall, drawn by the session's renderer into the runtime's swapchain images and read back before
release (tests/devices/xr/probe.py readback), equals the headless (EGL) renderer's frame of the same
per-eye cameras (the OpenXR views' off-axis frusta, ocular mode) pixel for pixel."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

XR = Path(__file__).resolve().parents[1] / "devices" / "xr"
sys.path.insert(0, str(XR))
sys.path.insert(0, str(XR.parents[1]))
from monado import runtime_env  # noqa: E402
from protocol_texts import TWO_INTERVAL_TAIL  # noqa: E402

REPO = XR.parents[2]
HEAD = """
psyop_protocol: 1
study: {name: xr_mesh, title: glTF candle and bottle before a blue wall in stereo}
display: {profile: vive_pro, eye_model: gullstrand_emsley_relaxed, ipd: tracker}
eyes: stereo
scene:
  - id: candle
    kind: mesh
    file: teaser.glb
    node: candle
    depth: {m: 0.6}
    centre_deg: [2, 0]
    size_deg: 12
  - id: bottle
    kind: mesh
    file: teaser.glb
    node: bottle
    depth: {m: 1}
    size_deg: 14
  - id: wall
    kind: quad
    width_deg: 60
    height_deg: 60
    depth: {D: 0.5}
    surface: {kind: solid, rgb: [0.2, 0.2, 0.6]}
"""


def test_a_mesh_frame_read_back_from_the_swapchain_equals_the_headless_render(tmp_path):
    shutil.copy(REPO / "assets" / "teaser.glb", tmp_path / "teaser.glb")
    tail = (TWO_INTERVAL_TAIL.replace("duration_s: 1}", "duration_s: 0.3}")
            .replace("{kind: response, expected_s: 1}", "{kind: response, expected_s: 0.2, timeout_s: 0.2}"))
    protocol = tmp_path / "xr_mesh.yaml"
    protocol.write_text(HEAD + tail)
    done = subprocess.run([sys.executable, str(XR / "probe.py"), "readback", str(protocol), "40", "egl"],
                          env=runtime_env(tmp_path), cwd=REPO, capture_output=True, text=True, timeout=300,
                          stdin=subprocess.DEVNULL)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert report["check_ok"]
    for eye in ("left", "right"):
        got = report["eyes"][eye]
        assert got["distinct_colours"] > 20, "candle, bottle and wall, not a flat frame"
        assert got["max_diff"] == 0 and got["n_diff"] == 0, got
