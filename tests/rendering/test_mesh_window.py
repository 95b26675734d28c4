"""Meshes on the window display (issue 26): the teaser's mesh scene drawn in a real glfw window under Xvfb
(tests/rendering/mesh_window_probe.py, its own process) holds the same pixels as the headless (EGL) frame of
the same scene and camera: the window shows what the headless renderer, the audit and the exactness tests see.
Both are llvmpipe here with the mesh pass's 4x MSAA; the stated tolerance is one 8-bit step per channel (the
window's float -> RGBA8 blit against the headless image rounded by image_uint8), and the test reports how many
pixels use it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from psyop.rendering import Renderer, RenderSettings

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mesh_window_probe import SIZE_PX, teaser_scene_and_camera
from test_window import x_display  # noqa: F401  (the module's Xvfb fixture)

REPO_ROOT = Path(__file__).resolve().parents[2]
PROBE = Path(__file__).resolve().with_name("mesh_window_probe.py")


def test_a_mesh_frame_in_a_window_equals_the_headless_frame(x_display, gl_context, tmp_path):  # noqa: F811
    out = tmp_path / "window.npz"
    env = dict(os.environ, DISPLAY=x_display, PYTHONPATH=str(REPO_ROOT))
    proc = subprocess.run([sys.executable, str(PROBE), str(out)], env=env, cwd=REPO_ROOT,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    info = json.loads(proc.stdout.strip().splitlines()[-1])
    if "unavailable" in info:
        pytest.skip(f"no window could be opened on {x_display}: {info['unavailable']}")
    window = np.load(out)
    scene, cam = teaser_scene_and_camera()
    with Renderer(scene, RenderSettings(reuse_tolerance_px=None), ctx=gl_context) as renderer:
        renderer.render(cam)
        headless = renderer.image_uint8().astype(np.int16)
    assert headless.shape == (SIZE_PX[1], SIZE_PX[0], 3)
    # the scene is not empty: candle and bottle both show in the crop
    assert len({tuple(p) for p in headless.reshape(-1, 3)}) > 20
    own = window["own"].astype(np.int16)
    screen = window["screen"].astype(np.int16)
    np.testing.assert_array_equal(own, headless)  # the window's context renders the headless frame
    diff = np.abs(screen - headless)
    assert diff.max() <= 1, (int(diff.max()), info)
    print(f"window vs headless ({info['renderer']}, max_samples {info['max_samples']}): "
          f"max |diff| {int(diff.max())}, {int((diff > 0).any(axis=-1).sum())} of {diff.shape[0] * diff.shape[1]} px differ")
