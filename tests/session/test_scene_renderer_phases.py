"""What a watching participant sees outside the intervals: the recalibration cross and the
blank frame (sec. 5.1: each trial starts by fixating a central cross)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.session.phases import PhaseSpec
from psyop.session.plan import compile_plan
from psyop.session.scene_renderer import SceneRenderer

REPO = Path(__file__).resolve().parents[2]
STRAIGHT_AHEAD_M = (0.032, 0.0, -1.0)


@pytest.fixture(scope="module")
def watched() -> SceneRenderer:
    protocol = load_protocol(REPO / "protocols" / "detection.yaml")
    renderer = SceneRenderer(compile_plan(protocol, tracker_ipd_m=0.064), scale=0.5)
    yield renderer
    renderer.close()


def _image(renderer: SceneRenderer, show: str, name: str) -> np.ndarray:
    protocol_row = compile_schedule(renderer.protocol, 1).iloc[0].to_dict()
    check = renderer.render(protocol_row, PhaseSpec(name, 0.5, show, "cross"), "conventional", 0.1, STRAIGHT_AHEAD_M)
    assert check.checked and check.ok
    return renderer._renderer.image(renderer.last_eye)


def test_recalibration_phase_shows_a_white_cross_at_the_eye_straight_ahead(watched: SceneRenderer) -> None:
    img = _image(watched, "cross", "recalibration")
    h, w, _ = img.shape
    white = np.all(img > 0.6, axis=2)  # brighter than the 0.5 background: covered (at least partly) by the cross
    ys, xs = np.nonzero(white)
    assert white.sum() > 10
    # a cross: the white pixels lie on the central row band or the central column band
    assert abs(xs.mean() - w / 2) < 2 and abs(ys.mean() - h / 2) < 2
    on_bands = (np.abs(ys + 0.5 - h / 2) < 3) | (np.abs(xs + 0.5 - w / 2) < 3)
    assert on_bands.all()
    assert np.allclose(img[0, 0], 0.5, atol=0.02)  # background elsewhere


def test_blank_phase_is_uniform_background(watched: SceneRenderer) -> None:
    img = _image(watched, "blank", "blank")
    assert np.ptp(img) == 0 and np.allclose(img, 0.5, atol=0.02)


def test_headless_sampled_checks_skip_cross_and_blank() -> None:
    protocol = load_protocol(REPO / "protocols" / "detection.yaml")
    renderer = SceneRenderer(compile_plan(protocol, tracker_ipd_m=0.064), scale=0.1, max_images=2)
    try:
        row = compile_schedule(protocol, 1).iloc[0].to_dict()
        check = renderer.render(row, PhaseSpec("recalibration", 0.5, "cross", "cross"), "conventional", 0.0,
                                STRAIGHT_AHEAD_M)
        assert not check.checked and renderer.images_rendered == 0
    finally:
        renderer.close()


def test_stimulus_follows_the_tracked_head_and_the_cross_does_not(watched: SceneRenderer) -> None:
    row = compile_schedule(watched.protocol, 1).iloc[0].to_dict()
    interval = PhaseSpec("interval1", 2.0, "stimulus", "pursuit", "mode_interval1", interval=1)
    turned = ((0.0, 0.0, 0.0), (np.cos(np.radians(1.0)), 0.0, np.sin(np.radians(1.0)), 0.0))  # 2 deg yaw
    still = ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))

    def image(phase: PhaseSpec, pose) -> np.ndarray:
        watched.render(row, phase, "conventional", 0.5, STRAIGHT_AHEAD_M, head_pose=pose)
        return watched._renderer.image(watched.last_eye).copy()

    assert not np.array_equal(image(interval, still), image(interval, turned))
    cross = PhaseSpec("recalibration", 0.5, "cross", "cross")
    assert np.array_equal(image(cross, still), image(cross, turned))
