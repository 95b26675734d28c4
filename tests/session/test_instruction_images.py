"""An image on an instruction page (``session: instructions: pages: image:``): decoded at validation, drawn on the
head-fixed panel above the page's text at its ``image_width_deg`` (psyop.rendering.text.picture_page), and found
in rendered frames (``psyop render --phase instructions`` and a session's own frame) where it was laid out: its
extent subtends the stated width to within a pixel, and the crop matches the source image resized to it. A file
that is missing or not an image, and an image too large for the view, are refused in one line at their key."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from psyop.cli import main
from psyop.errors import UserError
from psyop.protocol import load_protocol

REPO = Path(__file__).resolve().parents[2]
WIDTH_DEG = 10.0
PAGES = """
session:
  instructions:
    pages:
      - text: Look at the picture, then press a key.
        image: pictures/quadrants.png
        image_width_deg: WIDTH
      - text: A page without a picture.
"""
#: the source picture's quadrants: red, green / blue, yellow (full-scale channels read the same in any encoding)
QUADRANTS = ((255, 0, 0), (0, 255, 0), (0, 0, 255), (255, 255, 0))
#: the most a crop's mean absolute difference (of 1) from the source resized to it may be: the picture's four
#: quadrants resized with Pillow's box filter against the renderer's nearest texel fetch differ only on the seams
CROP_TOLERANCE = 0.03


def _write(tmp_path: Path, width: str = str(WIDTH_DEG), eyes: str = "right") -> Path:
    text = (REPO / "protocols" / "realism.yaml").read_text()
    text = re.sub(r"(?m)^(\s*repetitions:)\s*\d+", r"\g<1> 1", text).replace("eyes: right ", f"eyes: {eyes} ", 1)
    protocol = tmp_path / "pictured.yaml"
    protocol.write_text(text + PAGES.replace("WIDTH", width))
    (tmp_path / "pictures").mkdir(exist_ok=True)
    pixels = np.zeros((48, 64, 3), dtype=np.uint8)
    for k, rgb in enumerate(QUADRANTS):
        pixels[24 * (k // 2):24 * (k // 2 + 1), 32 * (k % 2):32 * (k % 2 + 1)] = rgb
    Image.fromarray(pixels).save(tmp_path / "pictures" / "quadrants.png")
    return protocol


def _picture_in(frame: np.ndarray) -> tuple[slice, slice]:
    """Rows and columns of the frame's saturated pixels (the picture's: the panel, its ink and the background are
    grey)."""
    saturated = frame.max(axis=2) - frame.min(axis=2) > 0.5
    rows, cols = np.nonzero(saturated)
    assert rows.size, "no picture in the frame"
    return slice(rows.min(), rows.max() + 1), slice(cols.min(), cols.max() + 1)


def _check_picture(frame: np.ndarray, tangents: tuple[float, float, float, float], source: Path) -> None:
    """The picture subtends WIDTH_DEG (to one pixel's angle at its edges), keeps the source's aspect ratio (to a
    pixel), lies above the page's text, and matches the source resized to its extent."""
    rows, cols = _picture_in(frame)
    left, right, _, _ = tangents
    width_px = frame.shape[1]

    def tan_at(col: int) -> float:
        return left + col / width_px * (right - left)

    width_deg = math.degrees(math.atan(tan_at(cols.stop)) - math.atan(tan_at(cols.start)))
    pixel_deg = math.degrees(math.atan(tan_at(cols.stop)) - math.atan(tan_at(cols.stop - 1)))
    assert abs(width_deg - WIDTH_DEG) <= pixel_deg + 1e-9, (width_deg, pixel_deg)
    h, w = rows.stop - rows.start, cols.stop - cols.start
    assert abs(h - w * 48 / 64) <= 1.0, (h, w)
    ink_rows = np.nonzero((frame.min(axis=2) > 0.9).any(axis=1))[0]
    assert ink_rows.size and ink_rows.min() >= rows.stop, "the text is not below the picture"
    expected = np.asarray(Image.open(source).convert("RGB").resize((w, h), Image.Resampling.BOX), float) / 255.0
    difference = float(np.abs(frame[rows, cols] - expected).mean())
    assert difference < CROP_TOLERANCE, difference


def test_render_draws_the_picture_above_the_text_at_its_width(tmp_path: Path) -> None:
    import matplotlib.image as mpimg

    protocol = _write(tmp_path)
    out = tmp_path / "page.png"
    assert main(["render", str(protocol), "--phase", "instructions", "--screen", "0", "--ipd-mm", "64",
                 "--antialiasing", "none", "--out", str(out)]) == 0
    side = json.loads(Path(str(out) + ".json").read_text())
    t = side["frustum_tangents"]
    frame = np.asarray(mpimg.imread(out), dtype=np.float64)[:, :, :3]
    _check_picture(frame, (t["left"], t["right"], t["bottom"], t["top"]), tmp_path / "pictures" / "quadrants.png")
    plain = tmp_path / "plain.png"  # the page without a picture draws none
    assert main(["render", str(protocol), "--phase", "instructions", "--screen", "1", "--ipd-mm", "64",
                 "--antialiasing", "none", "--out", str(plain)]) == 0
    grey = np.asarray(mpimg.imread(plain), dtype=np.float64)[:, :, :3]
    assert not (grey.max(axis=2) - grey.min(axis=2) > 0.5).any()


@pytest.fixture(scope="module")
def gl_context():
    from psyop.rendering.renderer import create_headless_context

    ctx = create_headless_context()
    yield ctx
    ctx.release()


def test_a_session_frame_shows_the_picture_where_laid_out(tmp_path: Path, gl_context) -> None:
    from psyop.session.plan import compile_plan
    from psyop.session.scene_renderer import SceneRenderer
    from psyop.session.screens import screens_of_kind

    protocol = _write(tmp_path)
    plan = compile_plan(load_protocol(protocol), tracker_ipd_m=0.064)
    assert plan.protocol.session is not None
    renderer = SceneRenderer(plan, scale=0.5, ctx=gl_context, owns_ctx=False)
    try:
        phase = screens_of_kind(plan.protocol.session, "instructions", done=0, total=1)[0].phase()
        assert phase.image == "pictures/quadrants.png" and phase.image_width_deg == WIDTH_DEG
        check = renderer.render({"trial": -1}, phase, "conventional", 0.1, (0.0, 0.0, -1.0))
        assert check.checked and check.ok
        frame = np.asarray(renderer._renderer.image("right"), dtype=np.float64)[:, :, :3]
        left, right, bottom, top = (float(t) for t in renderer.display.frustum_tangents("right"))
    finally:
        renderer.close()
    _check_picture(frame, (left, right, bottom, top), tmp_path / "pictures" / "quadrants.png")


def test_a_missing_file_or_one_that_is_no_image_is_refused_at_its_line(tmp_path: Path, capsys) -> None:
    protocol = _write(tmp_path)
    (tmp_path / "pictures" / "quadrants.png").write_text("not a picture")
    assert main(["validate", str(protocol)]) == 2
    err = capsys.readouterr().err.strip()
    line = next(i for i, text in enumerate(protocol.read_text().splitlines(), 1) if "image: pictures" in text)
    assert len(err.splitlines()) == 1 and f"pictured.yaml:{line}:" in err, err
    assert "at session.instructions.pages[0].image" in err and "quadrants.png" in err, err
    (tmp_path / "pictures" / "quadrants.png").unlink()
    assert main(["validate", str(protocol)]) == 2
    assert "image file 'pictures/quadrants.png' not found" in capsys.readouterr().err


def test_a_picture_too_wide_for_the_view_is_refused_at_its_width(tmp_path: Path, capsys) -> None:
    from psyop.session.plan import compile_plan
    from psyop.session.scene_renderer import SceneRenderer

    protocol = _write(tmp_path, width="110")
    assert main(["validate", str(protocol)]) == 0  # the view is the display's: known when a session starts
    line = next(i for i, text in enumerate(protocol.read_text().splitlines(), 1) if "image_width_deg" in text)
    with pytest.raises(UserError) as refused:
        SceneRenderer(compile_plan(load_protocol(protocol), tracker_ipd_m=0.064), scale=0.25)
    assert f"pictured.yaml:{line}:" in str(refused.value) and "give image_width_deg" in str(refused.value)
    assert main(["render", str(protocol), "--phase", "instructions", "--ipd-mm", "64", "--out",
                 str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "does not fit the view" in err, err
