"""Renderer cost and accuracy, side by side in one run.

1. Frame cost, ocular vs conventional rendering (same scene, same gaze trace, interleaved).
2. Anti-aliasing methods: accuracy against exact ray geometry (detection red area, ordinal
   border position, conventional-mode leak) and frame cost.
3. One eye vs two eyes per frame.

Full run: 1440x1600 frames (Vive Pro). ``quick``: a 360x400 window of the same camera around
the stimulus, fewer frames. Absolute llvmpipe times are context only; the ratios are the result.
"""

from __future__ import annotations

import math
import statistics
import time
from pathlib import Path

from psyop.rendering.builders import detection_stimulus, fixation_target
from psyop.rendering.camera_math import crop_camera
from psyop.rendering.measure import (
    RIGHT_CENTRE_M,
    border_position_errors,
    detection_area_errors,
    right_eye_camera,
)
from psyop.rendering.renderer import Renderer, RenderSettings, create_headless_context
from psyop.rendering.scene import Scene
from psyop.rendering.shaders import AntiAliasing


def _scene(k: int) -> Scene:
    back, front = detection_stimulus(2.0, 0.5, origin_m=RIGHT_CENTRE_M)
    phi = math.radians(k)  # the fixation target circles at 16 deg
    target = fixation_target(0.5, 16 * math.cos(phi), 16 * math.sin(phi), RIGHT_CENTRE_M)
    return Scene((back, front) + target)


def _camera(k: int, mode: str, quick: bool, eye: str = "right"):
    phi = math.radians(k)
    full = right_eye_camera(16 * math.cos(phi), 16 * math.sin(phi), mode)
    if eye == "left":
        full = right_eye_camera(16 * math.cos(phi), 16 * math.sin(phi), mode, eye="left")
    if not quick:
        return full
    return crop_camera(full, 720 - 180, 800 - 200, 360, 400)


def _time_frame(renderer: Renderer, cameras) -> float:
    start = time.perf_counter()
    for cam in cameras:
        renderer.render(cam)
    renderer.finish()
    return time.perf_counter() - start


def run(out_dir: Path, quick: bool) -> str:
    ctx = create_headless_context()
    n_frames = 4 if quick else 10
    size = "360x400 window (quick)" if quick else "1440x1600"
    no_reuse = RenderSettings(reuse_tolerance_px=None)
    lines = ["## Rendering: frame cost and anti-aliasing accuracy", "",
             f"llvmpipe ({ctx.info['GL_RENDERER']}), frames {size}, detection stimulus + circling fixation "
             "target, gaze pursuing the target at 16 deg; frame reuse off for timing.", ""]

    # 1. ocular vs conventional, interleaved frame by frame
    times = {"conventional": [], "ocular": []}
    edges = {"conventional": 0, "ocular": 0}
    with Renderer(_scene(0), no_reuse, ctx=ctx) as renderer:
        renderer.render(_camera(0, "ocular", quick))
        for k in range(n_frames):
            renderer.set_scene(_scene(k))
            for mode in (("ocular", "conventional") if k % 2 else ("conventional", "ocular")):
                times[mode].append(_time_frame(renderer, [_camera(k, mode, quick)]))
                edges[mode] += renderer.edge_pixel_count("right")
    med = {m: statistics.median(t) for m, t in times.items()}
    best = {m: min(t) for m, t in times.items()}
    lines += [f"**Ocular / conventional frame cost: {best['ocular'] / best['conventional']:.3f}** (fastest of "
              f"{n_frames} interleaved frames each; ratio of medians {med['ocular'] / med['conventional']:.3f}; "
              f"{best['ocular'] * 1e3:.0f} vs {best['conventional'] * 1e3:.0f} ms on a shared 2-core llvmpipe). "
              f"Deterministic work: {edges['ocular']} vs {edges['conventional']} adaptively supersampled "
              f"(edge) pixels over the same frames, ratio {edges['ocular'] / max(edges['conventional'], 1):.3f}; "
              "every other pixel costs the same in both modes.", ""]

    # 2. anti-aliasing table
    methods = [
        ("none (1 ray per pixel)", RenderSettings(antialiasing=AntiAliasing.NONE)),
        ("MSAA 2 (llvmpipe serves 4)", RenderSettings(antialiasing=AntiAliasing.MSAA, msaa_samples=2)),
        ("MSAA 4", RenderSettings(antialiasing=AntiAliasing.MSAA, msaa_samples=4)),
        ("supersampling 4x4", RenderSettings(antialiasing=AntiAliasing.SUPERSAMPLE, samples_per_axis=4)),
        ("adaptive ray-cast (32x32 at edges)", RenderSettings(antialiasing=AntiAliasing.ADAPTIVE)),
    ]
    if not quick:
        methods.insert(4, ("supersampling 8x8", RenderSettings(antialiasing=AntiAliasing.SUPERSAMPLE,
                                                                samples_per_axis=8)))
    lines += ["| anti-aliasing | worst red-area error (ocular, 9 configs) | red leaked in conventional (px^2) "
              "| max border error (px) | frame cost vs adaptive |", "|---|---|---|---|---|"]
    rows = []
    for label, settings in methods:
        area = detection_area_errors(settings, ctx)
        border = float(border_position_errors(settings, ctx).max())
        timed = RenderSettings(antialiasing=settings.antialiasing, samples_per_axis=settings.samples_per_axis,
                               msaa_samples=settings.msaa_samples, reuse_tolerance_px=None)
        with Renderer(_scene(0), timed, ctx=ctx) as renderer:
            renderer.render(_camera(0, "ocular", quick))
            renderer.finish()
            repeats = 1 if settings.samples_per_axis >= 8 and settings.antialiasing is AntiAliasing.SUPERSAMPLE else 3
            cost = min(_time_frame(renderer, [_camera(k + 1, "ocular", quick)]) for k in range(repeats))
        rows.append((label, area, border, cost))
    adaptive_cost = rows[-1][3]
    for label, area, border, cost in rows:
        lines.append(f"| {label} | {area.worst_relative * 100:.2f} % | {area.conventional_leak_px2:.3f} | "
                     f"{border:.3f} | {cost / adaptive_cost:.2f} ({cost * 1e3:.0f} ms) |")
    lines.append("")

    # 3. one eye vs two
    one, two = [], []
    with Renderer(_scene(0), no_reuse, ctx=ctx) as renderer:
        renderer.render(_camera(0, "ocular", quick))
        renderer.render(_camera(0, "ocular", quick, eye="left"))
        for k in range(n_frames):
            one.append(_time_frame(renderer, [_camera(k + 1, "ocular", quick)]))
            two.append(_time_frame(renderer, [_camera(k + 1, "ocular", quick),
                                              _camera(k + 1, "ocular", quick, eye="left")]))
    eye_ratio = min(two) / min(one)
    lines += [f"**Two eyes / one eye frame cost: {eye_ratio:.2f}** (monocular studies render only the right eye).",
              ""]
    ctx.release()
    (out_dir / "rendering_frames.txt").write_text("\n".join(lines) + "\n")
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover
    print(run(Path("/tmp"), quick=True))
