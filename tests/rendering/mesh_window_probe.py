"""Run in a fresh process (a GLX window cannot share a process with EGL contexts safely): draw the teaser's
mesh scene (protocols/examples/teaser.yaml, candle and bottle, ocular, gaze 20 deg left) in a glfw window on
$DISPLAY and save what the window holds, for tests/rendering/test_mesh_window.py to compare with the headless
frame of the same scene and camera.

``python mesh_window_probe.py OUT.npz``: writes ``screen`` (the window's back buffer read after the frame was
presented into it, before the swap), ``screen_after_swap`` (read again after the swap, as the timing probe
does) and ``own`` (the renderer's own frame in the window's context, image_uint8); prints JSON."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from psyop.optics.camera import EyeCamera, make_eye_camera
from psyop.optics.display import VIVE_PRO
from psyop.protocol.loader import load_protocol
from psyop.rendering import Renderer, RenderSettings, Scene
from psyop.rendering.builders import direction_from_angles
from psyop.rendering.camera_math import crop_camera, project_points_px
from psyop.rendering.measure import FIXTURE_IPD_M as IPD_M, NC_M, RIGHT_CENTRE_M

TEASER = Path(__file__).resolve().parents[2] / "protocols" / "examples" / "teaser.yaml"
SIZE_PX = (96, 160)  # width, height: the candle and the bottle beside it


def teaser_scene_and_camera() -> tuple[Scene, EyeCamera]:
    from psyop.stimulus import build_scene

    row = {"bottle_D": 1.0, "level_D": 2.33333, "trial_seed": 1}
    scene = build_scene(load_protocol(TEASER), row, 0.0, RIGHT_CENTRE_M, base_dir=TEASER.parent)
    fixation_m = RIGHT_CENTRE_M + direction_from_angles(-20.0, 0.0) * 1.0
    full = make_eye_camera(VIVE_PRO, "right", fixation_m, IPD_M, NC_M, "ocular", 0.01, 100.0)
    x, y = project_points_px(full, [RIGHT_CENTRE_M + np.array([0.0, 0.0, -1.0])])[0]
    return scene, crop_camera(full, int(x) - 40, int(y) - 80, *SIZE_PX)


def main(out: Path) -> int:
    from psyop.rendering.window import Window, WindowUnavailable

    try:
        window = Window(*SIZE_PX, "psyop mesh test", swap_interval=0)
    except WindowUnavailable as error:
        print(json.dumps({"unavailable": str(error)}))
        return 0
    scene, cam = teaser_scene_and_camera()
    with window, Renderer(scene, RenderSettings(reuse_tolerance_px=None), ctx=window.ctx) as renderer:
        renderer.render(cam)
        own = renderer.image_uint8()
        window.ctx.copy_framebuffer(window.ctx.screen, renderer.framebuffer("right"))
        screen = window.screen_pixels().copy()
        window.present(renderer.framebuffer("right"))
        after = window.screen_pixels().copy()
        info = {"renderer": window.ctx.info["GL_RENDERER"], "max_samples": int(window.ctx.max_samples)}
    np.savez(out, screen=screen, screen_after_swap=after, own=own)
    print(json.dumps(info))
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1])))
