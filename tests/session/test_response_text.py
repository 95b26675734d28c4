"""The participant reads the response phase's text in the headset (issue 9): the prompt (else the
question) rasterised once, drawn as a head-fixed panel 1 m straight ahead with 1 deg letters. Checked on
rendered frames against the panel's exact screen rectangle, in mono and in stereo (both eyes, the panel
at 1 m from the head origin, so each eye sees it at its own place: disparity)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from psyop.protocol import parse_protocol
from psyop.rendering import Renderer
from psyop.rendering.renderer import create_headless_context
from psyop.rendering.text import text_image
from psyop.schedule import compile_schedule
from psyop.session.plan import compile_plan
from psyop.session.scene_renderer import SceneRenderer
from psyop.stimulus import blank_scene, scene_origin_m, text_scene

REPO = Path(__file__).resolve().parents[2]
REALISM = (REPO / "protocols" / "realism.yaml").read_text()
PROMPT = "Which stimulus gave a stronger impression of realistic depth?"
SCALE = 0.5


@pytest.fixture(scope="module")
def gl_context():
    ctx = create_headless_context()
    yield ctx
    ctx.release()


def _plan(text: str):
    return compile_plan(parse_protocol(text, str(REPO / "protocols" / "study.yaml")), tracker_ipd_m=0.064)


def _screen_rect_px(camera, corners_m: np.ndarray) -> tuple[float, float, float, float]:
    """x0, y0, x1, y1 (pixels, y down) of head-space points through the camera's exact pixel_to_ray."""
    inverse = np.linalg.inv(np.asarray(camera.pixel_to_ray, dtype=np.float64))
    uv = []
    for p in corners_m:
        q = inverse @ (p - np.asarray(camera.centre_of_projection_m))
        uv.append((q[0] / q[2] * camera.width_px, q[1] / q[2] * camera.height_px))
    xs, ys = zip(*uv)
    return min(xs), min(ys), max(xs), max(ys)


def _response_frames(plan, gl_context) -> dict[str, tuple[np.ndarray, np.ndarray, tuple[float, ...]]]:
    """Per eye: (frame of the response phase, the same frame blank, the panel's exact screen rectangle)."""
    renderer = SceneRenderer(plan, scale=SCALE, ctx=gl_context, owns_ctx=False)
    try:
        row = compile_schedule(plan.protocol, 1).iloc[0].to_dict()
        fixation = (0.0, 0.0, -1.0)
        phase = plan.response.phase
        check = renderer.render(row, phase, phase.mode, 0.2, fixation)
        assert check.checked and check.ok
        renderer.render(row, phase, phase.mode, 0.4, fixation)
        assert renderer._texts.rasterisations == 1
        out = {}
        for eye in plan.rig.eyes:
            camera = plan.rig.camera(renderer.display, eye, fixation, phase.mode)
            seen = renderer._renderer.image(eye).copy()
            with Renderer(blank_scene(), ctx=gl_context, settings=renderer.settings) as blank:
                blank.render(camera)
                without = blank.image(eye).copy()
            shown = renderer._texts.image(PROMPT)
            panel = text_scene(shown, scene_origin_m(plan.protocol, plan.rig.centre_m(eye))).primitives[0]
            c, u, v = (np.asarray(x, dtype=np.float64) for x in (panel.centre_m, panel.half_u_m, panel.half_v_m))
            corners = np.array([c - u - v, c + u - v, c - u + v, c + u + v])
            out[eye] = (seen, without, _screen_rect_px(camera, corners))
        return out
    finally:
        renderer.close()


def _assert_text_exactly_in_rect(seen: np.ndarray, without: np.ndarray, rect: tuple[float, ...]) -> None:
    x0, y0, x1, y1 = rect
    h, w, _ = seen.shape
    assert 0 < x0 < x1 < w and 0 < y0 < y1 < h
    differs = np.any(np.abs(seen - without) > 1e-3, axis=2)
    xs = np.arange(w) + 0.5
    ys = np.arange(h) + 0.5
    inside = ((ys[:, None] > y0 + 1) & (ys[:, None] < y1 - 1)) & ((xs[None, :] > x0 + 1) & (xs[None, :] < x1 - 1))
    near = ((ys[:, None] > y0 - 1) & (ys[:, None] < y1 + 1)) & ((xs[None, :] > x0 - 1) & (xs[None, :] < x1 + 1))
    # (an anti-aliased glyph edge can average to the background grey: most, not all, covered pixels differ)
    assert differs[inside].mean() > 0.9, "the panel does not cover its screen rectangle"
    assert not differs[~near].any(), "pixels outside the panel's screen rectangle changed"
    rows, cols = np.nonzero(differs)  # the changed pixels span the rectangle, to the pixel
    assert cols.min() == pytest.approx(x0, abs=1.0) and cols.max() + 1 == pytest.approx(x1, abs=1.0)
    assert rows.min() == pytest.approx(y0, abs=1.0) and rows.max() + 1 == pytest.approx(y1, abs=1.0)
    # the text shows: ink brighter than the background inside the panel, the dark panel around it
    panel = seen[inside]
    assert (panel.max(axis=1) > 0.7).mean() > 0.02 and (panel.max(axis=1) < 0.3).mean() > 0.5


def test_text_image_has_ink() -> None:
    image = text_image(PROMPT)
    assert 0.02 < image.ink_fraction < 0.5
    assert image.width_em > image.height_em > 2  # two lines (wrapped at 40 characters), padded


def test_mono_response_phase_shows_the_prompt_in_its_exact_rectangle(gl_context) -> None:
    plan = _plan(REALISM)
    assert plan.response.participant_text == PROMPT
    frames = _response_frames(plan, gl_context)
    assert set(frames) == {"right"}
    seen, without, rect = frames["right"]
    _assert_text_exactly_in_rect(seen, without, rect)


def test_panel_size_and_depth() -> None:
    image = text_image(PROMPT)
    panel = text_scene(image, np.zeros(3)).primitives[0]
    assert panel.centre_m == (0.0, 0.0, -1.0)  # 1 m (1 D) straight ahead of the scene origin
    em_m = 2 * math.tan(math.radians(0.5))  # one em subtends 1 deg at 1 m
    assert panel.half_v_m[1] == pytest.approx(image.height_em * em_m / 2)
    assert panel.half_u_m[0] / panel.half_v_m[1] == pytest.approx(image.width_em / image.height_em)


def test_stereo_response_phase_shows_the_prompt_to_both_eyes_with_disparity(gl_context) -> None:
    frames = _response_frames(_plan(REALISM.replace("eyes: right ", "eyes: stereo ", 1)), gl_context)
    assert set(frames) == {"left", "right"}
    for seen, without, rect in frames.values():
        _assert_text_exactly_in_rect(seen, without, rect)
    # one panel 1 m ahead of the head origin: the left eye sees it to the right of where the right eye does
    (left_rect, right_rect) = frames["left"][2], frames["right"][2]
    assert left_rect[0] - right_rect[0] != pytest.approx(0.0, abs=1.0)


def test_without_a_prompt_the_question_is_shown_and_display_off_shows_nothing() -> None:
    plan = _plan(REALISM.replace("      prompt: " + PROMPT, "", 1))
    assert plan.response.prompt is None and plan.response.participant_text == plan.response.question
    egocentric = compile_plan(parse_protocol((REPO / "protocols" / "egocentric.yaml").read_text(), "egocentric.yaml",
                                              base_dir=REPO / "protocols"),
                              tracker_ipd_m=0.064)
    assert egocentric.response.display_off and egocentric.response.participant_text is None


def test_render_command_shows_the_response_text(tmp_path) -> None:
    import json

    import matplotlib.image as mpimg

    from psyop.cli import main

    out = tmp_path / "response.png"
    assert main(["render", str(REPO / "protocols" / "realism.yaml"), "--phase", "response", "--ipd-mm", "64",
                 "--antialiasing", "none", "--out", str(out)]) == 0
    side = json.loads(Path(str(out) + ".json").read_text())
    assert side["phase"] == "response" and side["response_text"] == PROMPT and side["primitives"] == ["response_text"]
    img = mpimg.imread(out)[:, :, :3]
    h, w, _ = img.shape
    centre = img[h // 2 - 10:h // 2 + 10, w // 2 - 40:w // 2 + 40]
    assert (centre.max(axis=2) > 0.9).any() and (centre.max(axis=2) < 0.2).any()  # ink on the dark panel
    assert np.allclose(img[0, 0], 0.5, atol=0.01)  # background elsewhere


def test_text_is_rasterised_at_the_display_pixel_density() -> None:
    from psyop.optics.display import get_display_profile as display_profile
    from psyop.rendering.text import em_px_for_display

    display = display_profile("vive_pro")
    em_px = em_px_for_display(display, 1.0)
    # one em (1 deg at 1 m straight ahead) covers about em_px display pixels at the image centre
    em_on_screen_px = display.height_px / (display.tan_top - display.tan_bottom) * 2 * math.tan(math.radians(0.5))
    assert abs(em_px - em_on_screen_px) <= 0.5 and em_px >= 8


def test_a_blank_prompt_falls_back_to_the_question() -> None:
    plan = _plan(REALISM.replace("      prompt: " + PROMPT, '      prompt: "   "', 1))
    assert plan.response.participant_text == plan.response.question
