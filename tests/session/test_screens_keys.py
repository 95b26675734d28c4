"""A default prompt names the keys of the response source in use, and is drawn legibly in a real window.

Without a ``prompt:`` the participant reads the question and, for each answer, the inputs of the session's response
source that give it (the kind's own maps: keyboard keys, response-box buttons, OpenXR controller triggers). In a
glfw window under Xvfb (subprocess: a GLX window shares no process with EGL contexts) the response phase is
rendered and presented per source at the window's default scale; the test reads the window's pixels back and checks
that the panel is drawn exactly where the layout's text panel projects, that it holds as many ink lines as the
layout has, and that each line's capitals (measured in the window's own pixels) are at least MIN_CAP_HEIGHT_PX."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from psyop.protocol import load_protocol, parse_protocol
from psyop.protocol.kinds import kind_of
from psyop.protocol.kinds.base import Inputs, input_name, inputs_text
from psyop.rendering.text import MIN_CAP_HEIGHT_PX
from psyop.session.plan import compile_plan

REPO = Path(__file__).resolve().parents[2]
DETECTION = REPO / "protocols" / "detection.yaml"
SOURCES = ("keyboard", "serial:/dev/ttyUSB0", "openxr")
#: what the default prompt of protocols/detection.yaml (two_interval, no prompt:) says under its question, per source
EXPECTED_KEYS = {"keyboard": "first interval: 1 / left arrow\nsecond interval: 2 / right arrow",
                 "serial:/dev/ttyUSB0": "first interval: button 1 / button L\nsecond interval: button 2 / button R",
                 "openxr": "first interval: left trigger\nsecond interval: right trigger"}


def test_the_default_prompt_names_each_sources_inputs_from_the_kinds_maps() -> None:
    protocol = load_protocol(DETECTION)
    question = protocol.response.question
    for source, keys in EXPECTED_KEYS.items():
        plan = compile_plan(protocol, responses=source)
        assert plan.response.prompt is None and plan.response.keeps_lines
        assert plan.response.participant_text == f"{question}\n\n{keys}"
        assert plan.response.as_dict()["answer_keys"] == keys
        inputs = kind_of(protocol.response).inputs(protocol.response)
        raw = {"keyboard": inputs.keys, "serial:/dev/ttyUSB0": inputs.buttons, "openxr": inputs.controller}[source]
        for name in raw:  # every input of the kind's map is named (a keypad twin of a named digit aside)
            spoken = input_name(source.partition(":")[0], name)  # type: ignore[arg-type]
            assert spoken in keys or (name.startswith("kp_") and name.removeprefix("kp_") in raw)
    for source in ("sim", "none", None):  # nobody reads keys: the question alone, as before
        plan = compile_plan(protocol, responses=source)
        assert plan.response.participant_text == question and "answer_keys" not in plan.response.as_dict()


def test_a_given_prompt_is_kept_and_a_rating_scale_names_its_own_keys() -> None:
    text = DETECTION.read_text().replace("    - kind: response\n",
                                         "    - kind: response\n      prompt: Press a key.\n", 1)
    assert "prompt: Press a key." in text
    plan = compile_plan(parse_protocol(text, str(DETECTION)), responses="keyboard")
    assert plan.response.participant_text == "Press a key." and not plan.response.keeps_lines
    rating = compile_plan(load_protocol(REPO / "protocols" / "examples" / "rating.yaml"), responses="keyboard")
    assert rating.response.answer_keys is None  # its scale's lines give each point's digit (key and button)
    assert rating.response.participant_text.endswith(rating.response.response_text)


def test_inputs_text_groups_by_answer_and_names_each_input() -> None:
    inputs = Inputs({"left": "near", "l": "near", "right": "far", "kp_2": "far", "space": "far"},
                    {"L": "near"}, {})
    assert inputs_text(inputs, "keyboard", {"near": "nearer"}) == "nearer: left arrow / L\nfar: right arrow / " \
                                                                   "keypad 2 / space bar"
    assert inputs_text(inputs, "serial") == "near: button L"
    assert inputs_text(inputs, "openxr") is None  # no controller answers: nothing to name


SCRIPT = textwrap.dedent(
    """
    import json
    import numpy as np
    from pathlib import Path
    from psyop.devices.window import GlfwWindow
    from psyop.protocol import load_protocol
    from psyop.schedule import compile_schedule
    from psyop.session.clock import VirtualClock
    from psyop.session.plan import compile_plan
    from psyop.session.scene_renderer import SceneRenderer
    from psyop.stimulus import scene_origin_m, text_scene

    protocol = load_protocol(Path({protocol!r}))
    row = compile_schedule(protocol, 1).iloc[0].to_dict()
    out = {{}}
    window = None
    for source in {sources!r}:
        plan = compile_plan(protocol, responses=source)
        if window is None:
            window = GlfwWindow(plan.display, VirtualClock(), scale={scale!r}, n_eyes=len(plan.rig.eyes))
        renderer = SceneRenderer(plan, scale={scale!r}, ctx=window.gl_context, owns_ctx=False)
        phase = plan.response.phase
        request = window.begin_frame(0.0)
        renderer.render(row, phase, phase.mode, 0.0, (0.0, 0.0, -1.0), frame=request)
        window.end_frame(request, renderer.eye_textures())
        screen = window._window.screen_pixels().astype(np.float64) / 255.0
        eye = plan.rig.eyes[0]
        text = plan.response.participant_text
        image = renderer._texts.image(text, keep_lines=plan.response.keeps_lines)
        panel = text_scene(image, scene_origin_m(plan.protocol, plan.rig.centre_m(eye))).primitives[0]
        camera = plan.rig.camera(renderer.display, eye, (0.0, 0.0, -1.0), "conventional")
        inverse = np.linalg.inv(np.asarray(camera.pixel_to_ray, dtype=np.float64))
        corners = []
        for du in (-1, 1):
            for dv in (-1, 1):
                p = np.asarray(panel.centre_m) + du * np.asarray(panel.half_u_m) + dv * np.asarray(panel.half_v_m)
                q = inverse @ (p - np.asarray(camera.centre_of_projection_m))
                corners.append((q[0] / q[2] * camera.width_px, q[1] / q[2] * camera.height_px))
        layout = renderer._texts.layout(text, plan.response.keeps_lines)
        out[source] = {{"text": text, "lines": list(layout.lines), "rect": [min(c[0] for c in corners),
                       min(c[1] for c in corners), max(c[0] for c in corners), max(c[1] for c in corners)],
                       "eye_px": [camera.width_px, camera.height_px]}}
        np.save(Path({tmp!r}) / (source.partition(":")[0] + ".npy"), screen)
        renderer.close()
    window.close()
    print(json.dumps(out))
    """
)


def _line_heights_px(frame, threshold: float) -> list[int]:
    import numpy as np

    rows = np.nonzero((frame.max(axis=2) > threshold).any(axis=1))[0]
    return [len(run) for run in np.split(rows, np.nonzero(np.diff(rows) > 1)[0] + 1)] if rows.size else []


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs xvfb-run (Debian xvfb)")
def test_a_window_shows_each_sources_default_prompt_legibly_where_its_panel_is(tmp_path: Path) -> None:
    import numpy as np

    script = SCRIPT.format(protocol=str(DETECTION), sources=SOURCES, scale=0.25, tmp=str(tmp_path))
    result = subprocess.run(["xvfb-run", "-a", sys.executable, "-c", script], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    shown = json.loads(result.stdout.strip().splitlines()[-1])
    for source in SOURCES:
        drawn = shown[source]
        keys = EXPECTED_KEYS[source]
        assert drawn["text"].endswith(keys)
        assert " ".join(drawn["lines"]).split() == drawn["text"].split()  # every word laid out, in order
        screen = np.load(tmp_path / (source.partition(":")[0] + ".npy"))
        width, height = drawn["eye_px"]
        assert screen.shape[:2] == (height, width)
        x0, y0, x1, y1 = drawn["rect"]
        assert 0 < x0 < x1 < width and 0 < y0 < y1 < height  # the panel lies inside the window's frame
        background = screen[1, 1]
        differs = np.any(np.abs(screen - background) > 2.5 / 255, axis=2)
        xs, ys = np.arange(width) + 0.5, np.arange(height) + 0.5
        inside = (ys[:, None] > y0 + 1) & (ys[:, None] < y1 - 1) & (xs[None, :] > x0 + 1) & (xs[None, :] < x1 - 1)
        near = (ys[:, None] > y0 - 1) & (ys[:, None] < y1 + 1) & (xs[None, :] > x0 - 1) & (xs[None, :] < x1 + 1)
        assert differs[inside].mean() > 0.9 and not differs[~near].any()  # drawn exactly where the panel is
        ink = screen[inside].max(axis=1)
        assert (ink > 0.7).mean() > 0.02  # light ink on the dark panel
        heights = _line_heights_px(np.where(near[:, :, None], screen, 0.0), 0.6)
        assert len(heights) == len([line for line in drawn["lines"] if line.strip()])  # a band per line of text
        # a line's band spans its tallest glyph (a capital or an ascender, descenders below): at least the minimum
        assert min(heights) >= MIN_CAP_HEIGHT_PX, heights
