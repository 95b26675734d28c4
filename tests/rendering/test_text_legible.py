"""Legible text on every display and scale (docs/rendering.md, "Legible text"): measured on rendered frames.

The response phase's text is rendered by the session's SceneRenderer (mono and stereo, the Vive Pro profile at
several scales, 0.25 the window's default); each text line's capitals are measured in the frame (rows with ink of
at least half coverage, a prompt of capitals only, so a line's ink height is its capital height) and must be at
least MIN_CAP_HEIGHT_PX, every line drawn, and the whole panel inside the frame. The former layout (1 deg letters
whatever the pixels) measures below the minimum at every scale by the same measure. Text that cannot fit at the minimum
is refused when the renderer is built, naming the protocol line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from psyop.errors import UserError
from psyop.protocol import parse_protocol
from psyop.rendering import Renderer
from psyop.rendering.text import (INK_RGB, MIN_CAP_HEIGHT_PX, MIN_EM_DEG, PANEL_RGB, WRAP_CHARS, em_px_for_display,
                                  text_image)
from psyop.schedule import compile_schedule
from psyop.session.plan import compile_plan
from psyop.session.scene_renderer import SceneRenderer
from psyop.stimulus import scene_origin_m, text_scene

REPO = Path(__file__).resolve().parents[2]
REALISM = (REPO / "protocols" / "realism.yaml").read_text()
PROMPT = "Which stimulus gave a stronger impression of realistic depth?"
CAPITALS = "NEAR OR FAR THEN PRESS THE KEY THAT NAMES IT HERE"  # no descenders: a line's ink height is its capitals'
HALF_INK = (max(INK_RGB) + max(PANEL_RGB)) / 2.0  # a pixel at least half covered by ink


def _plan(eyes: str = "right", prompt: str = CAPITALS, session: str = ""):
    text = REALISM.replace(PROMPT, prompt, 1).replace("eyes: right ", f"eyes: {eyes} ", 1) + session
    return compile_plan(parse_protocol(text, str(REPO / "protocols" / "legible.yaml")), tracker_ipd_m=0.064)


def _line_heights_px(frame: np.ndarray) -> list[int]:
    """The heights of the frame's text lines: runs of rows holding a pixel at least half covered by ink."""
    rows = np.nonzero((frame.max(axis=2) > HALF_INK).any(axis=1))[0]
    if rows.size == 0:
        return []
    return [len(run) for run in np.split(rows, np.nonzero(np.diff(rows) > 1)[0] + 1)]


def _assert_panel_inside(frame: np.ndarray) -> None:
    """The panel (every pixel that is not the background grey) lies inside the frame, clear of its edges."""
    background = frame[0, 0]
    assert np.allclose(frame[[0, 0, -1, -1], [0, -1, 0, -1]], background, atol=1e-3)
    drawn = np.any(np.abs(frame - background) > 1e-3, axis=2)
    rows, cols = np.nonzero(drawn)
    h, w = drawn.shape
    assert rows.size > 0 and rows.min() > 0 and cols.min() > 0 and rows.max() < h - 1 and cols.max() < w - 1


def _response_frames(plan, gl_context, scale: float):
    renderer = SceneRenderer(plan, scale=scale, ctx=gl_context, owns_ctx=False)
    try:
        row = compile_schedule(plan.protocol, 1).iloc[0].to_dict()
        phase = plan.response.phase
        check = renderer.render(row, phase, phase.mode, 0.2, (0.0, 0.0, -1.0))
        assert check.checked and check.ok
        layout = renderer._texts.layout(plan.response.participant_text, plan.response.keeps_lines)
        return {eye: renderer._renderer.image(eye).copy() for eye in plan.rig.eyes}, layout
    finally:
        renderer.close()


@pytest.mark.parametrize("eyes, scale", [("right", 0.25), ("right", 0.5), ("right", 1.0), ("stereo", 0.25),
                                         ("stereo", 0.6)])
def test_rendered_capitals_are_at_least_the_minimum_and_inside_the_frame(gl_context, eyes, scale) -> None:
    frames, layout = _response_frames(_plan(eyes), gl_context, scale)
    assert layout is not None and layout.em_deg >= MIN_EM_DEG
    for eye, frame in frames.items():
        heights = _line_heights_px(frame)
        assert len(heights) == len(layout.lines), (eye, heights, layout.lines)  # every line drawn, lines apart
        assert min(heights) >= MIN_CAP_HEIGHT_PX, (eye, scale, heights)
        _assert_panel_inside(frame)
    if scale == 0.25:  # too few pixels per degree for 40 characters a line: the text grew and wrapped narrower
        assert layout.em_deg > 5 * MIN_EM_DEG and layout.wrap_chars < WRAP_CHARS


@pytest.mark.parametrize("scale", [0.25, 0.5, 1.0])
def test_the_former_one_degree_letters_measure_below_the_minimum(gl_context, scale) -> None:
    """The same measure on the former layout (1 deg letters at the display's density) fails at every scale, even the
    Vive Pro's full resolution (about 7 px there, 1 px at 0.25): what the rule fixes."""
    plan = _plan()
    renderer = SceneRenderer(plan, scale=scale, ctx=gl_context, owns_ctx=False)
    display = renderer.display
    renderer.close()
    former = text_image(CAPITALS, em_px_for_display(display, 1.0))
    eye = plan.rig.eyes[0]
    scene = text_scene(former, scene_origin_m(plan.protocol, plan.rig.centre_m(eye)), letter_height_deg=1.0)
    with Renderer(scene, ctx=gl_context) as r:
        r.render(plan.rig.camera(display, eye, (0.0, 0.0, -1.0), "conventional"))
        heights = _line_heights_px(r.image(eye))
    assert heights and max(heights) < MIN_CAP_HEIGHT_PX and (scale > 0.25 or max(heights) < MIN_CAP_HEIGHT_PX / 4)


LONG_PAGE = "\\n".join(f"Line {i} of a page that is long enough to fill forty characters." for i in range(8))
INSTRUCTIONS = f"""
session:
  instructions:
    pages:
      - text: Welcome.
      - text: "{LONG_PAGE}"
"""


def test_text_that_cannot_fit_is_refused_at_start_naming_its_protocol_line(gl_context) -> None:
    plan = _plan(session=INSTRUCTIONS)
    SceneRenderer(plan, scale=1.0, ctx=gl_context, owns_ctx=False).close()  # fits at full resolution
    with pytest.raises(UserError) as refused:
        SceneRenderer(plan, scale=0.25, ctx=gl_context, owns_ctx=False)
    line = next(i for i, text in enumerate(plan.protocol.source_text.splitlines(), 1) if "Line 0 of" in text)
    assert refused.value.location is not None and refused.value.location.endswith(f"legible.yaml:{line}:15")
    message = str(refused.value)
    assert "\n" not in message and "split it into pages" in message and "--window-scale" in message
    # nothing is laid out (or refused) where no text is drawn: sampled headless checks
    SceneRenderer(plan, scale=0.25, ctx=gl_context, owns_ctx=False, max_images=2).close()


def test_psyop_render_draws_the_prompt_as_the_session_does(tmp_path: Path) -> None:
    """`psyop render --phase response` previews the text at the session's legible size, not 1 deg letters (about
    7 px tall on this display at full resolution)."""
    from PIL import Image

    from psyop.cli import main

    protocol = tmp_path / "legible.yaml"
    protocol.write_text(REALISM.replace(PROMPT, CAPITALS, 1))
    assert main(["render", str(protocol), "--phase", "response", "--out", str(tmp_path / "r.png")]) == 0
    frame = np.asarray(Image.open(tmp_path / "r.png").convert("RGB")).astype(np.float64) / 255.0
    heights = _line_heights_px(frame)
    assert heights and min(heights) >= MIN_CAP_HEIGHT_PX, heights
    _assert_panel_inside(frame)
