"""Run in a child process by the headset tests: opens psyop's OpenXR display on the test runtime and
reports what it saw as one JSON line. Usage: probe.py MODE PROTOCOL [FRAMES [GRAPHICS]]
(GRAPHICS: the OpenGL binding, auto, egl or xlib; xlib needs an X display)

- cameras: per frame, the views, head pose and gaze the display and tracking sources read, and the
  cameras psyop builds from them (centre of projection, rays through the image's edge midpoints);
- readback: one stimulus frame rendered into the swapchain images, read back before release, and
  the same cameras rendered by a separate headless renderer;
- teardown: what fd 0 is before the display opens and after it closes, and the open fds;
- abandon: a frame's stimulus drawn into the swapchain images many times over, then the display
  closed with the frame still open and the draws still queued (what a Ctrl-C mid-frame leaves).
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np


def main() -> None:
    mode, protocol_path = sys.argv[1], Path(sys.argv[2])
    n_frames = int(sys.argv[3]) if len(sys.argv) > 3 else 40
    graphics = sys.argv[4] if len(sys.argv) > 4 else "auto"
    from psyop.protocol import load_protocol
    from psyop.session.clock import RealClock
    from psyop.session.plan import compile_plan
    from psyop.devices.xr.display import OpenXRDisplay

    plan = compile_plan(load_protocol(protocol_path))
    clock = RealClock()
    fd0_before = os.readlink("/proc/self/fd/0")
    fds_before = sorted(os.listdir("/proc/self/fd"))
    display = OpenXRDisplay(plan, clock, graphics=graphics)
    out: dict = {"summary_open": display.summary()}
    try:
        display.wait_until_ready()
        if mode == "cameras":
            out["frames"] = _cameras(plan, display, n_frames)
        elif mode == "readback":
            out.update(_readback(plan, display, protocol_path))
        elif mode == "abandon":
            out.update(_abandon(display, n_frames))
    finally:
        display.close()
    out["summary"] = display.summary()
    out["fd0_before"], out["fd0_after"] = fd0_before, os.readlink("/proc/self/fd/0")
    out["fds_before"], out["fds_after"] = fds_before, sorted(os.listdir("/proc/self/fd"))
    print(json.dumps(out))


def _cameras(plan, display, n_frames: int) -> list[dict]:
    from psyop.devices.xr.tracking import OpenXRGaze, OpenXRPose, OpenXRResponses
    from psyop.protocol.kinds import kind_named

    gaze = OpenXRGaze.on_display(display) if display.runtime.gaze_space is not None else None
    pose = OpenXRPose.on_display(display, "right")
    aim = OpenXRPose.on_display(display, "right:aim")
    buttons = OpenXRResponses.on_display(display, kind_named("two_interval"))
    rt = display.runtime
    stage = rt._reference_space(rt.xr.ReferenceSpaceType.STAGE)  # where the runtime puts LOCAL's origin
    frames = []
    for _ in range(n_frames):
        request = display.begin_frame(0.0)
        sample = gaze.latest(0.0) if gaze is not None else None
        head = pose.head(0.0)
        aim.head(0.0)
        fixation = sample.fixation_m if sample is not None and sample.valid else (0.0, 0.0, -1.0)
        record = {"display_time_s": request.display_time_s, "period_s": request.period_s,
                  "should_render": request.should_render, "missed": request.missed_frames,
                  "head": [list(head.position_m), list(head.orientation_wxyz), head.valid] if head else None,
                  "gaze": [sample.timestamp_s, list(sample.fixation_m), sample.valid] if sample else None,
                  "hand": [list(h.position_m) + list(h.orientation_wxyz) + [h.valid] for h in pose.hand({}, 1e9, 1, None)],
                  "aim": [list(h.position_m) + list(h.orientation_wxyz) + [h.valid] for h in aim.hand({}, 1e9, 1, None)],
                  "response": None, "views": {},
                  "stage_in_world": list(rt.locate(stage, rt.world, display.frame_time_ns).position_m)}
        response = buttons.collect({"correct_interval": 2}, request.display_time_s)
        if response is not None:
            record["response"] = response.response
        for view in request.views:
            target = request.targets[view.eye]
            cams = {}
            for m in ("conventional", "ocular"):
                cam = plan.rig.view_camera(view, target.width_px, target.height_px, fixation, m)
                w, h = cam.width_px, cam.height_px
                rays = {name: (cam.pixel_to_ray @ np.array([x / w, y / h, 1.0])).tolist()
                        for name, (x, y) in {"left": (0, h / 2), "right": (w, h / 2), "top": (w / 2, 0),
                                             "bottom": (w / 2, h)}.items()}
                cams[m] = {"cop": cam.centre_of_projection_m.tolist(), "rays": rays, "valid": cam.valid}
            record["views"][view.eye] = {"centre": list(view.centre_m), "q": list(view.orientation_wxyz),
                                         "tangents": list(view.tangents), "size": [target.width_px, target.height_px],
                                         "cameras": cams}
        display.end_frame(request, [])
        frames.append(record)
    return frames


def _abandon(display, n_draws: int) -> dict:
    """Begin a frame and queue ``n_draws`` full-image draws of a costly shader into each eye's
    swapchain image, with nothing that waits for them; return with the frame open."""
    ctx = display.gl_context
    program = ctx.program(
        vertex_shader="#version 330\nin vec2 p; void main() { gl_Position = vec4(p, 0.0, 1.0); }",
        fragment_shader="#version 330\nout vec4 c; void main() { float a = 0.0;"
                        " for (int i = 0; i < 64; ++i) a += sin(gl_FragCoord.x * 0.01 + float(i));"
                        " c = vec4(fract(a), 0.5, 0.5, 1.0); }")
    quad = ctx.buffer(np.array([-1, -1, 1, -1, -1, 1, 1, 1], dtype="f4").tobytes())
    vao = ctx.vertex_array(program, [(quad, "2f", "p")])
    while True:
        request = display.begin_frame(0.0)
        if request.should_render and request.targets:
            break
        display.end_frame(request, [])
    for target in request.targets.values():
        target.framebuffer.use()
        for _ in range(n_draws):
            vao.render(mode=5)  # triangle strip: the whole image
    return {"draws_queued": n_draws, "frame_open": display._frame is not None}


def _readback(plan, display, protocol_path: Path) -> dict:
    from psyop.rendering import Renderer
    from psyop.rendering.renderer import create_headless_context
    from psyop.schedule import compile_schedule
    from psyop.session.scene_renderer import SceneRenderer
    from psyop.stimulus import build_scene

    renderer = SceneRenderer(plan, ctx=display.gl_context, owns_ctx=False)
    row = compile_schedule(plan.protocol, 1).iloc[0].to_dict()
    phase = next(p for p in plan.phases if p.show == "stimulus")
    fixation = (0.05, 0.02, -0.8)
    while True:
        request = display.begin_frame(0.0)
        if request.should_render and request.targets:
            break
        display.end_frame(request, [])
    check = renderer.render(row, phase, "ocular", 0.1, fixation, frame=request)
    shown, cameras = {}, {}
    for eye, target in request.targets.items():
        raw = target.framebuffer.read(components=4, dtype="f1")
        shown[eye] = np.frombuffer(raw, np.uint8).reshape(target.height_px, target.width_px, 4)[::-1, :, :3]
        cameras[eye] = plan.rig.view_camera(request.view(eye), target.width_px, target.height_px, fixation, "ocular")
    display.end_frame(request, renderer.eye_textures())
    renderer.close()
    ctx = create_headless_context()  # an independent renderer in its own context
    result = {"check_ok": check.ok, "eyes": {}}
    for eye, camera in cameras.items():
        scene = build_scene(plan.protocol, row, 0.1, plan.rig.centre_m(eye), interval=max(1, phase.interval),
                            base_dir=protocol_path.parent)
        with Renderer(scene, ctx=ctx) as headless:
            headless.render(camera)
            reference = headless.image_uint8(eye)
        diff = np.abs(shown[eye].astype(int) - reference.astype(int))
        result["eyes"][eye] = {"shape": list(shown[eye].shape), "max_diff": int(diff.max()),
                               "n_diff": int(np.count_nonzero(diff.max(axis=2))),
                               "distinct_colours": int(len(np.unique(reference.reshape(-1, 3), axis=0)))}
    ctx.release()
    return result


if __name__ == "__main__":
    main()
