"""Run in a fresh process (a GLX window cannot share a process with EGL contexts safely):
open a glfw window on $DISPLAY, present 20 paced frames with a deliberate stall, print JSON."""

from __future__ import annotations

import json
import sys
import time


from psyop.rendering import Renderer, RenderSettings, Scene, Solid
from psyop.rendering.builders import frontoparallel_disc
from psyop.rendering.camera_math import crop_camera
from psyop.rendering.window import Window, WindowUnavailable, run_paced
from psyop.rendering.measure import RIGHT_CENTRE_M as RIGHT_EYE_CENTRE_M
from psyop.rendering.measure import right_eye_camera as gaze_camera

REFRESH_S = 1.0 / 90.0
STALL_FRAME = 10


def main() -> int:
    try:
        window = Window(64, 64, "psyop test")
    except WindowUnavailable as error:
        print(json.dumps({"unavailable": str(error)}))
        return 0
    disc = frontoparallel_disc(1.0, 4.0, Solid((0.0, 1.0, 0.0)), origin_m=RIGHT_EYE_CENTRE_M)
    settings = RenderSettings(samples_per_axis=4)  # timing, not accuracy, is under test here
    with window, Renderer(Scene((disc,), background=(0.0, 0.0, 0.5)), settings, ctx=window.ctx) as renderer:

        def frame(k: int) -> None:
            cam = crop_camera(gaze_camera(0.5 * k, 0.0, "ocular"), 720 - 32, 800 - 32, 64, 64)
            renderer.render(cam)
            window.present(renderer.framebuffer("right"))
            if k == STALL_FRAME:
                time.sleep(4.5 * REFRESH_S)  # not a wait: a stall that must show up as dropped frames

        timing = run_paced(20, REFRESH_S, frame)
        screen = window.screen_pixels()
        renderer_name = window.ctx.info["GL_RENDERER"]
    print(json.dumps({
        "present_s": timing.present_s.tolist(),
        "slot_start_s": timing.slot_start_s.tolist(),
        "dropped": timing.dropped_frames,
        "late": timing.late_frames,
        "centre_rgb": screen[32, 32].tolist(),
        "corner_rgb": screen[2, 2].tolist(),
        "renderer": renderer_name,
        "refresh_s": REFRESH_S,
        "stall_frame": STALL_FRAME,
    }))
    return 0


if __name__ == "__main__":
    sys.exit(main())
