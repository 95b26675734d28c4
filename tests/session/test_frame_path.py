"""The per-frame path of a real session (issue 13), measured as behaviour, not time:

- a checked frame reads back a reduced summary, never the whole float framebuffer;
- image surfaces are decoded once per session, not per frame and eye;
- stereo frames are reused like mono ones (set_scene alternating between the eyes used to
  reset every eye's reuse state: 0 of 20 reused with a still gaze).
Costs side by side: benchmarks/bench_frame_path.py.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest

from psyop.optics import VIVE_PRO, make_eye_camera
from psyop.protocol import load_protocol
from psyop.rendering import Renderer, RenderSettings, Scene, Solid
from psyop.rendering.scene import ImageTexture
from psyop.rendering.builders import frontoparallel_disc
from psyop.rendering.frame_check import FrameChecker, summarise_image
from psyop.rendering.renderer import create_headless_context
from psyop.schedule import compile_schedule
from psyop.session.phases import PhaseSpec
from psyop.session.plan import compile_plan
from psyop.session.scene_renderer import SceneRenderer

REPO = Path(__file__).resolve().parents[2]
IPD_M, NC_M = 0.064, 0.0076916
FIXATION_M = (0.0, 0.0, -1.0)


@pytest.fixture(scope="module")
def ctx():
    context = create_headless_context()
    yield context
    context.release()


def test_frame_check_matches_the_full_readback_and_reads_back_a_small_fraction(ctx) -> None:
    checker = FrameChecker(ctx, block_px=16)
    rng = np.random.default_rng(0)
    for h, w in [(64, 48), (161, 97)]:
        img = rng.random((h, w, 4)).astype(np.float32)
        tex = ctx.texture((w, h), 4, img.tobytes(), dtype="f4")
        for mutate in (None, "nan", "inf", "uniform"):
            if mutate == "nan":
                img[3, 5, 1] = np.nan
            elif mutate == "inf":
                img[h - 1, w - 1, 2] = -np.inf
            elif mutate == "uniform":
                img[:] = 0.5
            tex.write(img.tobytes())
            got, want = checker.summarise(tex), summarise_image(img)
            assert (got.n_pixels, got.n_nonfinite, got.min_value, got.max_value) == \
                   (want.n_pixels, want.n_nonfinite, want.min_value, want.max_value)
            assert got.ok(False) == want.ok(False) and got.ok(True) == want.ok(True)
            assert got.bytes_read * 100 < want.bytes_read
        tex.release()
    checker.release()


def test_a_session_frame_is_checked_without_reading_the_frame_back(monkeypatch: pytest.MonkeyPatch) -> None:
    protocol = load_protocol(REPO / "protocols" / "detection.yaml")
    renderer = SceneRenderer(compile_plan(protocol, tracker_ipd_m=IPD_M), scale=0.25)

    def no_readback(*_a, **_k):
        raise AssertionError("the whole frame was read back")

    monkeypatch.setattr(Renderer, "image", no_readback)
    try:
        row = compile_schedule(protocol, 1).iloc[0].to_dict()
        interval = PhaseSpec("interval1", 2.0, "stimulus", "pursuit", "mode_interval1", interval=1)
        check = renderer.render(row, interval, "ocular", 0.1, (0.032, 0.0, -1.0))
        assert check.checked and check.ok
        blank = renderer.render(row, PhaseSpec("blank", 0.5, "blank", "cross"), "conventional", 0.1, (0.032, 0.0, -1.0))
        assert blank.checked and blank.ok  # uniform by design
    finally:
        renderer.close()


def test_image_surfaces_are_decoded_once_per_session(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    text = (REPO / "protocols" / "detection.yaml").read_text()
    assert "surface: {kind: solid, rgb: [1, 0, 0]}" in text
    (tmp_path / "tex").mkdir()
    mpimg.imsave(tmp_path / "tex" / "red.png", np.dstack([np.ones((64, 64)), np.zeros((64, 64)), np.zeros((64, 64))]))
    path = tmp_path / "study.yaml"
    path.write_text(text.replace("surface: {kind: solid, rgb: [1, 0, 0]}", "surface: {kind: image, path: tex/red.png}", 1))
    protocol = load_protocol(path)
    decoded = []
    real_imread = mpimg.imread
    monkeypatch.setattr(mpimg, "imread", lambda p, *a, **k: decoded.append(p) or real_imread(p, *a, **k))
    renderer = SceneRenderer(compile_plan(protocol, tracker_ipd_m=IPD_M), scale=0.12)
    try:
        row = compile_schedule(protocol, 1).iloc[0].to_dict()
        interval = PhaseSpec("interval1", 2.0, "stimulus", "pursuit", "mode_interval1", interval=1)
        for k in range(5):
            assert renderer.render(row, interval, "ocular", 0.05 * k, (0.032, 0.0, -1.0)).ok
        textures = [p.material for p in renderer._renderer.scene.primitives
                    if isinstance(p.material, ImageTexture)]
        assert textures and float(textures[0].pixels[..., 0].min()) == 1.0  # the decoded file is in the scene
    finally:
        renderer.close()
    assert len(decoded) == 1


def test_stereo_frames_are_reused_like_mono_ones(ctx) -> None:
    centres = {"left": np.array([-IPD_M / 2, 0.0, 0.0]), "right": np.array([IPD_M / 2, 0.0, 0.0])}
    scenes = {eye: Scene((frontoparallel_disc(1.0, 4.0, Solid((1.0, 0.0, 0.0)), origin_m=c),), background=(0.5,) * 3)
              for eye, c in centres.items()}  # one scene per eye, as a session builds them
    small = dict(VIVE_PRO.__dict__, width_px=48, height_px=48)
    display = type(VIVE_PRO)(**small)
    cameras = {eye: make_eye_camera(display, eye, FIXATION_M, IPD_M, NC_M, "ocular") for eye in centres}
    with Renderer(scenes["left"], RenderSettings(samples_per_axis=2), ctx=ctx) as renderer:
        for _ in range(10):  # 20 stereo frames with a still gaze
            for eye in ("left", "right"):
                renderer.set_scene(scenes[eye])
                renderer.render(cameras[eye])
        assert renderer.stats.frames_requested == 20
        assert renderer.stats.frames_skipped == 18  # all but each eye's first
        left = renderer.image("left")
        renderer.set_scene(scenes["right"])
        renderer.set_scene(scenes["left"])
        assert np.array_equal(renderer.image("left"), left)  # the kept image is the left eye's own
        # a changed scene for one eye renders that eye again
        moved = Scene((frontoparallel_disc(0.9, 4.0, Solid((1.0, 0.0, 0.0)), origin_m=centres["left"]),),
                      background=(0.5,) * 3)
        renderer.set_scene(moved)
        assert renderer.render(cameras["left"]).rendered


def test_a_real_session_checks_a_sample_of_its_frames_and_says_which() -> None:
    """Real sessions check each eye's first image of every phase and then every
    WATCHED_CHECK_EVERY-th rendered one (the reduction is a full pass over the frame on llvmpipe)."""
    from psyop.session.scene_renderer import WATCHED_CHECK_EVERY

    protocol = load_protocol(REPO / "protocols" / "detection.yaml")
    renderer = SceneRenderer(compile_plan(protocol, tracker_ipd_m=IPD_M), scale=0.12, check_every=WATCHED_CHECK_EVERY)
    try:
        row = compile_schedule(protocol, 1).iloc[0].to_dict()
        interval = PhaseSpec("interval1", 2.0, "stimulus", "pursuit", "mode_interval1", interval=1)
        checked = [renderer.render(row, interval, "ocular", 0.0, (0.032 + 0.01 * k, 0.0, -1.0)).checked
                   for k in range(2 * WATCHED_CHECK_EVERY + 1)]  # a moving gaze: every frame renders
        assert [k for k, c in enumerate(checked) if c] == [0, WATCHED_CHECK_EVERY, 2 * WATCHED_CHECK_EVERY]
        blank = PhaseSpec("blank", 0.5, "blank", "cross")
        assert renderer.render(row, blank, "conventional", 0.0, (0.032, 0.0, -1.0)).checked  # a new phase
        assert renderer.render(row, interval, "ocular", 0.0, (0.05, 0.0, -1.0)).checked  # and back
    finally:
        renderer.close()
