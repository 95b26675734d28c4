"""The cost of a frame of the participant's text panel (docs/rendering.md, "Legible text"), before and after.

A frame is ``Renderer.render`` of the response phase's text panel (protocols/detection.yaml's default prompt with
the keyboard's keys) plus the readback of the image (llvmpipe renders lazily, so the readback is where the work
shows), wall time, on one EGL context, at sizes a session draws it: the window's default scale (0.25 of the
Vive Pro profile: 360x400), half scale (720x800) and the full profile (1440x1600). Rows:

- former: the text as before the legible-text rule, one em of 1 deg whatever the pixels (capitals of 2 to 6 px at
  the smaller sizes), the panel's outline at the renderer's default 32x32 edge samples;
- legible, 32x32 outline: the legible layout (capitals of at least 12 px: a larger panel) with the default edge
  samples;
- legible, 4x4 outline (what sessions draw): the same panel with ``edge_samples_per_axis=4``.

Rows run interleaved (blocks of frames in turn), the camera moving 1 mm per frame so no frame is reused; per row
the median frame time and its ratio to the former's. Absolute times are this machine's (llvmpipe, shared CPUs):
context only.
"""

from __future__ import annotations

import dataclasses
import statistics
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
SIZES_PX = ((360, 400), (720, 800), (1440, 1600))


def _scenes(plan: Any, display: Any) -> dict[str, Any]:
    from psyop.rendering.scene import Scene
    from psyop.rendering.text import display_views, em_px_for_display, layout_text, text_image
    from psyop.stimulus import text_scene

    text = plan.response.participant_text
    centre = plan.rig.centre_m("right")
    former = text_scene(text_image(text, em_px_for_display(display, 1.0), keep_lines=True), centre,
                        letter_height_deg=1.0)
    former = Scene((dataclasses.replace(former.primitives[0], edge_samples_per_axis=None),),
                   background=former.background)
    layout = layout_text(text, True, display_views(display, {"right": 0.0}))
    legible = text_scene(text_image(text, keep_lines=True, layout=layout), centre)
    default_edges = Scene((dataclasses.replace(legible.primitives[0], edge_samples_per_axis=None),),
                          background=legible.background)
    return {"former (1 deg em), 32x32 outline": former, "legible, 32x32 outline": default_edges,
            "legible, 4x4 outline (sessions)": legible}


def _frames_s(renderer: Any, plan: Any, display: Any, n: int, start: int) -> list[float]:
    out = []
    for k in range(start, start + n):
        camera = plan.rig.camera(display, "right", (0.001 * (k % 50), 0.0, -1.0), "conventional")
        t0 = time.perf_counter()
        renderer.render(camera)
        renderer.image("right")
        out.append(time.perf_counter() - t0)
    return out


def run(out_dir: Path, quick: bool) -> str:
    from psyop.optics.display import VIVE_PRO
    from psyop.protocol import load_protocol
    from psyop.rendering import Renderer, RenderSettings
    from psyop.rendering.renderer import create_headless_context
    from psyop.session.plan import compile_plan

    rounds, per_block = (2, 2) if quick else (5, 4)
    plan = compile_plan(load_protocol(REPO / "protocols" / "detection.yaml"), responses="keyboard")
    ctx = create_headless_context()
    lines = ["## The participant's text panel, per frame (bench_text_panel)", "",
             f"Median wall time of render + readback of the detection study's default prompt (keyboard keys), "
             f"{rounds} interleaved rounds of {per_block} frames per row; ratio to the former layout.", "",
             "| image (px) | panel | median frame (ms) | ratio |", "|---|---|---:|---:|"]
    settings = RenderSettings(reuse_tolerance_px=None)
    try:
        for width, height in SIZES_PX:
            display = dataclasses.replace(VIVE_PRO, width_px=width, height_px=height)
            renderers = {name: Renderer(scene, settings=settings, ctx=ctx)
                         for name, scene in _scenes(plan, display).items()}
            times: dict[str, list[float]] = {name: [] for name in renderers}
            for name, renderer in renderers.items():  # warm-up: shaders, texture upload
                _frames_s(renderer, plan, display, 1, 0)
            for r in range(rounds):
                for name, renderer in renderers.items():
                    times[name] += _frames_s(renderer, plan, display, per_block, 1 + r * per_block)
            base = statistics.median(next(iter(times.values())))
            for name, values in times.items():
                median = statistics.median(values)
                lines.append(f"| {width}x{height} | {name} | {median * 1000:.1f} | {median / base:.2f} |")
            for renderer in renderers.values():
                renderer.release()
    finally:
        ctx.release()
    return "\n".join(lines) + "\n"
