"""Legible text in a headset (docs/rendering.md, "Legible text"): on the real OpenXR runtime (Monado, headless, its
simulated HMD, whose swapchain images are far smaller than the protocol's Vive Pro profile), the response phase's
default prompt is laid out for each eye's swapchain image at its size and field of view, drawn into it, and read
back from the swapchain image: each line's ink is at least MIN_CAP_HEIGHT_PX rows tall, every line is drawn and the
panel lies inside the image. Without a runtime the test skips with the reason (tests/devices/xr/monado.py)."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

from monado import runtime_env
from test_openxr_sessions import REPO, _protocol

from psyop.rendering.text import INK_RGB, MIN_CAP_HEIGHT_PX, PANEL_RGB

HALF_INK = (max(INK_RGB) + max(PANEL_RGB)) / 2.0

SCRIPT = textwrap.dedent(
    """
    import json
    import numpy as np
    from pathlib import Path
    from psyop.devices.xr.display import OpenXRDisplay
    from psyop.protocol import load_protocol
    from psyop.schedule import compile_schedule
    from psyop.session.clock import RealClock
    from psyop.session.plan import compile_plan
    from psyop.session.scene_renderer import SceneRenderer

    plan = compile_plan(load_protocol(Path({protocol!r})), responses="openxr")
    display = OpenXRDisplay(plan, RealClock())
    out = {{}}
    try:
        display.wait_until_ready()
        renderer = SceneRenderer(plan, ctx=display.gl_context, owns_ctx=False)
        row = compile_schedule(plan.protocol, 1).iloc[0].to_dict()
        while True:
            request = display.begin_frame(0.0)
            if request.should_render and request.targets:
                break
            display.end_frame(request, [])
        phase = plan.response.phase
        check = renderer.render(row, phase, phase.mode, 0.0, (0.0, 0.0, -1.0), frame=request)
        for eye, target in request.targets.items():
            raw = target.framebuffer.read(components=4, dtype="f1")
            image = np.frombuffer(raw, np.uint8).reshape(target.height_px, target.width_px, 4)[::-1, :, :3]
            np.save(Path({tmp!r}) / f"{{eye}}.npy", image)
        display.end_frame(request, renderer.eye_textures())
        layout = renderer._texts.layout(plan.response.participant_text, plan.response.keeps_lines)
        out = {{"check_ok": check.ok, "text": plan.response.participant_text, "lines": list(layout.lines),
               "em_px": layout.em_px, "sizes": {{e: [t.width_px, t.height_px] for e, t in request.targets.items()}},
               "profile_px": [plan.display.width_px, plan.display.height_px]}}
        renderer.close()
    finally:
        display.close()
    print(json.dumps(out))
    """
)


def _line_heights_px(frame: np.ndarray) -> list[int]:
    rows = np.nonzero((frame.max(axis=2) / 255.0 > HALF_INK).any(axis=1))[0]
    return [len(run) for run in np.split(rows, np.nonzero(np.diff(rows) > 1)[0] + 1)] if rows.size else []


def test_the_prompt_is_legible_in_each_swapchain_image_at_its_own_size(tmp_path: Path) -> None:
    script = SCRIPT.format(protocol=str(_protocol(tmp_path, prompt=None)), tmp=str(tmp_path))
    result = subprocess.run([sys.executable, "-c", script], env=runtime_env(tmp_path), cwd=REPO, capture_output=True,
                            text=True, timeout=180, stdin=subprocess.DEVNULL)
    assert result.returncode == 0, result.stderr[-3000:]
    shown = json.loads(result.stdout.strip().splitlines()[-1])
    assert shown["check_ok"] and shown["text"].endswith("first interval: left trigger\nsecond interval: right trigger")
    assert set(shown["sizes"]) == {"left", "right"}
    for eye, (width, height) in shown["sizes"].items():
        assert width * height < shown["profile_px"][0] * shown["profile_px"][1] / 4  # the runtime's, not the profile's
        frame = np.load(tmp_path / f"{eye}.npy")
        assert frame.shape == (height, width, 3)
        heights = _line_heights_px(frame)
        assert len(heights) == len([line for line in shown["lines"] if line.strip()]), (eye, heights)
        assert min(heights) >= MIN_CAP_HEIGHT_PX, (eye, heights)
        background = frame[0, 0].astype(int)
        drawn = np.any(np.abs(frame.astype(int) - background) > 2, axis=2)
        rows, cols = np.nonzero(drawn)
        assert rows.min() > 0 and cols.min() > 0 and rows.max() < height - 1 and cols.max() < width - 1
