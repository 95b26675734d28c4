"""What the experimenter window's mirror costs the headset frame path (issue 45): the OpenXR frame path of
bench_openxr_frame with and without the mirror (psyop.devices.experimenter.MirroredDisplay), one eye mirrored
and both.

The same SceneRenderer draws the same protocol (detection: the noise disc over the red disc, a moving gaze) into
the runtime's swapchain images, one frame at a time with ``ctx.finish()`` after each, on the test runtime (Monado,
null compositor, simulated HMD) in a child process under Xvfb (the window needs a desktop display). Per frame:
begin_frame (xrWaitFrame .. acquire) -> render -> end_frame (xrEndFrame; with the mirror, the downscale queued
before it and the read-back and present after it), less the time blocked in xrWaitFrame (the runtime's pacing).
Blocks of frames alternate between the three paths (each first in turn), after one warm-up block of each. The mirror updates about 15 times a second, i.e. on every
frame of the test runtime's synthetic 20 Hz, so this is its worst case per frame; its own per-update cost
(MirroredDisplay.cost) is reported beside it. llvmpipe times: the ratio is the result.
"""

from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

from benchmarks.openxr_runtime import NO_RUNTIME, default_runtime_json

REPO = Path(__file__).resolve().parents[1]
PATHS = ("no mirror", "mirror left eye", "mirror both eyes")


def _child(n_frames: int, blocks: int) -> dict:
    from psyop.devices.experimenter import MIRROR_WIDTH_PX, ExperimenterWindow, MirroredDisplay
    from psyop.devices.xr.display import OpenXRDisplay
    from psyop.protocol import load_protocol
    from psyop.schedule import compile_schedule
    from psyop.session.clock import RealClock
    from psyop.session.plan import compile_plan
    from psyop.session.scene_renderer import SceneRenderer

    plan = compile_plan(load_protocol(REPO / "protocols" / "detection.yaml"))
    clock = RealClock()
    row = compile_schedule(plan.protocol, 1).iloc[0].to_dict()
    phase = next(p for p in plan.phases if p.show == "stimulus")
    xr_display = OpenXRDisplay(plan, clock)
    xr_display.wait_until_ready()
    facts = xr_display.runtime.facts
    width, height = facts.recommended_sizes_px[0]
    renderer = SceneRenderer(plan, ctx=xr_display.gl_context, owns_ctx=False)
    mirror_px = (MIRROR_WIDTH_PX, round(MIRROR_WIDTH_PX * height / width))
    windows, displays = [], {"no mirror": xr_display}
    for name, eyes in (("mirror left eye", ("left",)), ("mirror both eyes", ("left", "right"))):
        window = ExperimenterWindow(clock, 1, mirror_px, egl=facts.graphics != "xlib", restore=xr_display.gl_context,
                                    eyes=eyes)
        windows.append(window)
        displays[name] = MirroredDisplay(xr_display, window)
    times: dict[str, list[float]] = {name: [] for name in PATHS}
    k = 0
    for block in range(blocks + 1):  # block 0 warms every path up (shaders, first read-backs): not counted
        for name in PATHS[block % len(PATHS):] + PATHS[:block % len(PATHS)]:  # each path first in turn
            display = displays[name]
            for _ in range(n_frames):
                k += 1
                waited_before = xr_display.wait_frame_s
                start = time.perf_counter()
                request = display.begin_frame(clock.now_s())
                renderer.render(row, phase, "ocular", 0.01 * k, (0.28 + 0.01 * (k % 7), 0.0, -1.0), frame=request)
                display.end_frame(request, renderer.eye_textures())
                renderer._renderer.ctx.finish()
                if block:
                    times[name].append((time.perf_counter() - start - (xr_display.wait_frame_s - waited_before)) * 1e3)
    costs = {name: displays[name].cost() for name in PATHS[1:]}  # type: ignore[union-attr]
    summary = xr_display.summary()
    for name in PATHS[1:]:
        displays[name].close()  # type: ignore[union-attr]
    for window in windows:
        window.close()
    renderer.close()
    xr_display.close()
    return {"size": [width, height], "runtime": summary["runtime"], "system": summary["system"],
            "graphics": facts.graphics, "mirror_px": list(mirror_px),
            "median_ms": {n: statistics.median(t) for n, t in times.items()},
            "p95_ms": {n: sorted(t)[int(0.95 * (len(t) - 1))] for n, t in times.items()},
            "frames": {n: len(t) for n, t in times.items()}, "mirror_cost": costs}


def run(out: Path, quick: bool) -> str:
    runtime = os.environ.get("XR_RUNTIME_JSON") or default_runtime_json() or NO_RUNTIME
    head = "## The experimenter window's mirror on the headset frame path (bench_openxr_mirror)\n\n"
    try:
        import glfw  # noqa: F401
        import xr  # noqa: F401
    except ImportError as exc:
        return head + f"Skipped: pyopenxr or glfw is not installed ({exc}).\n"
    if not Path(runtime).is_file():
        return head + f"Skipped: no OpenXR runtime at {runtime} (build it: bash ../shared/openxr/build-monado.sh).\n"
    xvfb_run = shutil.which("xvfb-run")
    if xvfb_run is None:
        return head + "Skipped: needs xvfb-run (Debian xvfb) for the window.\n"
    n, blocks = (10, 2) if quick else (40, 3)
    env = dict(os.environ, XR_RUNTIME_JSON=runtime, XRT_COMPOSITOR_NULL="1", SIMULATED_ENABLE="1", XRT_LOG="warning")
    code = (f"import json, sys; sys.path.insert(0, {str(REPO)!r}); from benchmarks.bench_openxr_mirror import _child; "
            f"print(json.dumps(_child({n}, {blocks})))")
    done = subprocess.run([xvfb_run, "-a", "-s", "-screen 0 1280x720x24", sys.executable, "-c", code], env=env,
                          cwd=REPO, capture_output=True, text=True, timeout=900, stdin=subprocess.DEVNULL)
    if done.returncode != 0:
        return head + f"Failed (exit {done.returncode}):\n\n```\n{done.stderr[-2000:]}\n```\n"
    r = json.loads(done.stdout.strip().splitlines()[-1])
    (out / "openxr_mirror.json").write_text(json.dumps(r, indent=1))
    return head + _table(r, blocks)


def _table(r: dict, blocks: int) -> str:
    base = r["median_ms"]["no mirror"]
    rows = [f"| {name} | {r['median_ms'][name]:.2f} | {r['p95_ms'][name]:.2f} | {r['median_ms'][name] / base:.2f} |"
            for name in PATHS]
    cost = [f"| {name} | {c['mirror_updates']} | {c['queue_before_submit']['median_ms']:.3f} | "
            f"{c['readback_and_present_after_submit']['median_ms']:.2f} |" for name, c in r["mirror_cost"].items()]
    return "\n".join([
        f"Protocol detection, {r['size'][0]}x{r['size'][1]} px swapchain, mirror {r['mirror_px'][0]}x"
        f"{r['mirror_px'][1]} px per eye, {r['frames']['no mirror']} frames per path in {blocks} alternating blocks; "
        f"runtime {r['runtime']} ({r['system']}, null compositor, OpenGL through {r['graphics']}), under Xvfb.",
        "",
        "| path | median ms per frame (xrWaitFrame excluded) | p95 ms | ratio to no mirror |",
        "|---|---|---|---|",
        *rows,
        "",
        "| mirror | updates | median ms queued before xrEndFrame | median ms read back and shown after |",
        "|---|---|---|---|",
        *cost,
        "",
        "The read-back and present run after xrEndFrame, in the time the loop would otherwise wait in xrWaitFrame; "
        "they delay no submitted frame while they fit that slack. llvmpipe times: the ratio is the result, and a "
        "GPU headset at 90 Hz (11.1 ms per frame) was not measured here.",
    ]) + "\n"
