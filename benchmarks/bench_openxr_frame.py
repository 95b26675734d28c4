"""Per-frame cost of the OpenXR display path over the headless path, at equal resolution (issue 16).

Both paths run the same SceneRenderer on the same protocol (detection: one eye, the noise disc
over the red disc, a moving gaze) at the runtime's recommended swapchain size, one frame at a
time with ``ctx.finish()`` after each so the GPU work is inside the frame:

- headless: HeadlessDisplay.begin_frame -> render -> end_frame;
- openxr: OpenXRDisplay.begin_frame (xrWaitFrame, xrBeginFrame, xrLocateViews, acquire swapchain
  images) -> render into the swapchain images -> end_frame (release, xrEndFrame with a projection
  layer), less the time blocked in xrWaitFrame (the runtime's pacing, not psyop's cost).

Runs in a child process on the test runtime (Monado, null compositor, simulated HMD: build it with
../shared/openxr/build-monado.sh); blocks of frames alternate between the paths. On llvmpipe the
ratio is the result; the 90 Hz budget (11.1 ms per stereo frame) is what a GPU must show, and
neither this machine nor the test runtime (a synthetic 20 Hz) can measure it.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from benchmarks.openxr_runtime import NO_RUNTIME, default_runtime_json

REPO = Path(__file__).resolve().parents[1]


def _child(n_frames: int, blocks: int) -> dict:
    import dataclasses

    from psyop.protocol import load_protocol
    from psyop.schedule import compile_schedule
    from psyop.session.clock import RealClock
    from psyop.session.frames import HeadlessDisplay
    from psyop.session.plan import compile_plan
    from psyop.session.scene_renderer import SceneRenderer
    from psyop.devices.xr.display import OpenXRDisplay

    plan = compile_plan(load_protocol(REPO / "protocols" / "detection.yaml"))
    clock = RealClock()
    row = compile_schedule(plan.protocol, 1).iloc[0].to_dict()
    phase = next(p for p in plan.phases if p.show == "stimulus")
    xr_display = OpenXRDisplay(plan, clock)
    xr_display.wait_until_ready()
    width, height = xr_display.runtime.facts.recommended_sizes_px[1]
    headless_plan = dataclasses.replace(plan, display=dataclasses.replace(plan.display, width_px=width, height_px=height))
    headless = HeadlessDisplay(clock, float(plan.display.refresh_hz))
    from psyop.rendering.renderer import create_headless_context

    headless_renderer = SceneRenderer(headless_plan, ctx=create_headless_context())
    xr_renderer = SceneRenderer(plan, ctx=xr_display.gl_context, owns_ctx=False)
    times: dict[str, list[float]] = {"headless": [], "openxr": []}
    k = 0
    for _ in range(blocks):
        for name, display, renderer in (("headless", headless, headless_renderer),
                                        ("openxr", xr_display, xr_renderer)):
            for _ in range(n_frames):
                k += 1
                fixation = (0.28 + 0.01 * (k % 7), 0.0, -1.0)
                waited_before = xr_display.wait_frame_s
                start = time.perf_counter()
                request = display.begin_frame(clock.now_s())
                renderer.render(row, phase, "ocular", 0.01 * k, fixation, frame=request)
                display.end_frame(request, renderer.eye_textures())
                renderer._renderer.ctx.finish()
                elapsed = time.perf_counter() - start - (xr_display.wait_frame_s - waited_before)
                times[name].append(elapsed * 1e3)
    summary = xr_display.summary()
    headless_renderer.close()
    xr_renderer.close()
    xr_display.close()
    return {"size": [width, height], "runtime": summary["runtime"], "system": summary["system"],
            "median_ms": {n: statistics.median(t) for n, t in times.items()},
            "frames": {n: len(t) for n, t in times.items()}}


def run(out: Path, quick: bool) -> str:
    runtime = os.environ.get("XR_RUNTIME_JSON") or default_runtime_json() or NO_RUNTIME
    head = "## OpenXR frame path over headless (bench_openxr_frame)\n\n"
    try:
        import xr  # noqa: F401
    except ImportError as exc:
        return head + f"Skipped: pyopenxr is not installed ({exc}).\n"
    if not Path(runtime).is_file():
        return head + f"Skipped: no OpenXR runtime at {runtime} (build it: bash ../shared/openxr/build-monado.sh).\n"
    n, blocks = (10, 2) if quick else (40, 3)
    env = dict(os.environ, XR_RUNTIME_JSON=runtime, XRT_COMPOSITOR_NULL="1", SIMULATED_ENABLE="1", XRT_LOG="warning")
    code = (f"import json, sys; sys.path.insert(0, {str(REPO)!r}); from benchmarks.bench_openxr_frame import _child; "
            f"print(json.dumps(_child({n}, {blocks})))")
    done = subprocess.run([sys.executable, "-c", code], env=env, cwd=REPO, capture_output=True, text=True, timeout=900)
    if done.returncode != 0:
        return head + f"Failed (exit {done.returncode}):\n\n```\n{done.stderr[-2000:]}\n```\n"
    r = json.loads(done.stdout.strip().splitlines()[-1])
    (out / "openxr_frame.json").write_text(json.dumps(r, indent=1))
    h, x = r["median_ms"]["headless"], r["median_ms"]["openxr"]
    return head + "\n".join([
        f"Protocol detection (one eye), {r['size'][0]}x{r['size'][1]} px, {r['frames']['openxr']} frames per path "
        f"in {blocks} alternating blocks; runtime {r['runtime']} ({r['system']}, null compositor).",
        "",
        "| path | median ms per frame (render + display, xrWaitFrame excluded) |",
        "|---|---|",
        f"| headless | {h:.2f} |",
        f"| openxr | {x:.2f} |",
        f"| ratio openxr / headless | {x / h:.2f} |",
        "",
        "Absolute times are llvmpipe's and mean little; on a headset at 90 Hz the whole stereo frame must fit "
        "11.1 ms, which only a GPU and a real runtime can show (not measured here).",
    ]) + "\n"
