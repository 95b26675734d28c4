"""Rendering off the paper's path, against exact geometry: optical infinity (0 D), coplanar
primitives and stereo disparity (issue 9, item 3). Each test failed on the code before the fix."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest

from psyop.cli import main
from psyop.optics.camera import make_eye_camera
from psyop.optics.display import VIVE_PRO
from psyop.protocol import load_protocol
from psyop.rendering import Renderer, RenderSettings, Scene, Solid
from psyop.rendering.builders import direction_from_angles, frontoparallel_disc
from psyop.rendering.camera_math import crop_camera, project_points_px
from psyop.rendering.transform import scene_in_head
from psyop.schedule import compile_schedule
from psyop.stimulus import build_scene, interval_mode
from protocol_texts import TWO_INTERVAL_TAIL

REPO = Path(__file__).resolve().parents[2]
PROTOCOLS = REPO / "protocols"
IPD_M = 0.064
NC_M = 0.0076916
RIGHT_C = np.array([IPD_M / 2, 0.0, 0.0])
MODES = ("conventional", "ocular", "reversed")
SETTINGS = RenderSettings(reuse_tolerance_px=None)


def _camera(eye: str, mode: str, gaze_deg=(16.0, 0.0), fixation_m: float = 1.0):
    centre = np.array([(-0.5 if eye == "left" else 0.5) * IPD_M, 0.0, 0.0])
    fixation = centre + direction_from_angles(*gaze_deg) * fixation_m
    return make_eye_camera(VIVE_PRO, eye, fixation, IPD_M, NC_M, mode)


def _crop(camera, centre_px, half_px: int):
    return crop_camera(camera, int(centre_px[0]) - half_px, int(centre_px[1]) - half_px, 2 * half_px, 2 * half_px)


def _red_area_px(img: np.ndarray) -> float:
    return float(np.sum(img[..., 0].astype(np.float64) - img[..., 1]))


def _coverage_centroid(cov: np.ndarray) -> tuple[float, float, float]:
    """(area px^2, x, y) of a coverage image: x, y its centroid in the image's pixels (x right,
    y down, pixel centres at +0.5)."""
    h, w = cov.shape
    ys, xs = np.mgrid[0:h, 0:w]
    area = float(cov.sum())
    return area, float((cov * (xs + 0.5)).sum() / area), float((cov * (ys + 0.5)).sum() / area)


# -- optical infinity -----------------------------------------------------------------------------

def _discrimination_back_disc():
    protocol = load_protocol(PROTOCOLS / "discrimination.yaml")
    row = compile_schedule(protocol, 0).iloc[0].to_dict()
    scene = build_scene(protocol, row, 0.0, RIGHT_C, interval=1)
    return scene, {p.name: p for p in scene.primitives}


def test_zero_dioptre_disc_renders_with_exact_area_and_no_parallax_in_every_mode(gl_context):
    _, by_name = _discrimination_back_disc()
    back = by_name["back"]
    assert back.at_infinity
    # Exact: a 2 deg frontoparallel disc at infinity straight ahead is the cone through the circle
    # of radius tan(1 deg) on the plane z = -1 (a direction set); the Vive Pro image is at
    # infinity, so pixel x = (tan_x - L) / (R - L) * W exactly: an ellipse with these radii.
    left, right, bottom, top = VIVE_PRO.frustum_tangents("right")
    rho = math.tan(math.radians(1.0))
    rx = rho * VIVE_PRO.width_px / (right - left)
    ry = rho * VIVE_PRO.height_px / (top - bottom)
    exact_area = math.pi * rx * ry
    exact_centre = (-left / (right - left) * VIVE_PRO.width_px, top / (top - bottom) * VIVE_PRO.height_px)
    results = {}
    with Renderer(Scene((back,)), SETTINGS, ctx=gl_context) as renderer:
        for mode in MODES:
            full = _camera("right", mode)
            x0, y0 = int(exact_centre[0]) - 24, int(exact_centre[1]) - 24
            renderer.render(crop_camera(full, x0, y0, 48, 48))
            img = renderer.image()
            area, cx, cy = _coverage_centroid(img[..., 0] - img[..., 1])
            results[mode] = (area, x0 + cx, y0 + cy)
            assert area == pytest.approx(exact_area, rel=0.005), f"{mode}: {area:.2f} px^2 vs exact {exact_area:.2f}"
            assert math.hypot(x0 + cx - exact_centre[0], y0 + cy - exact_centre[1]) < 0.01
    # zero parallax: the centre-of-projection translation (ocular, reversed) does not move it at all
    assert results["conventional"] == results["ocular"] == results["reversed"]


def test_zero_dioptre_stays_put_when_the_head_translates(gl_context):
    _, by_name = _discrimination_back_disc()
    scene = Scene((by_name["back"],))
    moved = scene_in_head(scene, (0.05, -0.02, 0.1), (1.0, 0.0, 0.0, 0.0))
    assert moved.primitives[0].centre_m == scene.primitives[0].centre_m


def test_render_command_draws_optical_infinity(tmp_path):
    """The issue's command: the red back disc (0 D) shows as a crescent beside the front disc."""
    out = tmp_path / "frame.png"
    rc = main(["render", str(PROTOCOLS / "discrimination.yaml"), "--trial", "0", "--gaze-deg", "16,0", "--mode",
               "ocular", "--crop", "656,736,128,128", "--out", str(out)])
    assert rc == 0
    img = mpimg.imread(out)[..., :3].astype(np.float64)
    red = (img[..., 0] > 0.6) & (img[..., 1] < 0.3)
    assert red.sum() >= 5


# -- coplanar primitives --------------------------------------------------------------------------

def test_coplanar_primitives_later_listed_wins(gl_context):
    big = frontoparallel_disc(0.5, 4.0, Solid((1.0, 0.0, 0.0)), origin_m=RIGHT_C, name="big")
    small = frontoparallel_disc(0.5, 1.0, Solid((0.0, 1.0, 0.0)), origin_m=RIGHT_C, name="small")
    far_big = frontoparallel_disc(math.inf, 4.0, Solid((1.0, 0.0, 0.0)), name="far_big")
    far_small = frontoparallel_disc(math.inf, 1.0, Solid((0.0, 1.0, 0.0)), name="far_small")
    cam = _camera("right", "ocular", (10.0, 5.0))
    centre = project_points_px(cam, [small.centre_m])[0]
    crop = _crop(cam, centre, 8)
    with Renderer(Scene((big,)), SETTINGS, ctx=gl_context) as renderer:
        for order, winner in (((big, small), 1), ((small, big), 0), ((far_big, far_small), 1),
                              ((far_small, far_big), 0)):
            renderer.set_scene(Scene(order))
            renderer.render(crop)
            rgb = renderer.image()[8, 8]
            assert rgb[winner] == pytest.approx(1.0) and rgb[1 - winner] == pytest.approx(0.0), order


def test_detection_at_level_zero_shows_no_red_in_any_interval_or_mode(gl_context):
    """At level 0 D the front (noise) disc is coplanar with the red back disc and listed after it,
    so it covers it: no red in any of the 45 level-0 trials, either interval, any mode."""
    protocol = load_protocol(PROTOCOLS / "detection.yaml")
    schedule = compile_schedule(protocol, 0)
    rows = schedule[schedule["level_D"] == 0]
    assert len(rows) == 45
    cams = {mode: _camera("right", mode, (16 * math.cos(0.7), 16 * math.sin(0.7))) for mode in MODES}
    worst = 0.0
    renderer = None
    try:
        for row in rows.to_dict("records"):
            for interval in (1, 2):
                scene = build_scene(protocol, row, 0.0, RIGHT_C, interval=interval)
                scene = Scene(tuple(p for p in scene.primitives if not p.name.startswith("fixation")))
                back = next(p for p in scene.primitives if p.name == "back")
                if renderer is None:
                    renderer = Renderer(scene, SETTINGS, ctx=gl_context)
                renderer.set_scene(scene)
                for mode in {interval_mode(protocol, row, interval), *MODES}:
                    crop = _crop(cams[mode], project_points_px(cams[mode], [back.centre_m])[0], 24)
                    renderer.render(crop)
                    worst = max(worst, _red_area_px(renderer.image()))
    finally:
        if renderer is not None:
            renderer.release()
    assert worst < 1e-3, f"red area {worst:.3f} px^2 at level 0"


# -- stereo ---------------------------------------------------------------------------------------

STEREO_DISC = """
psyop_protocol: 1
study: {name: stereo_disc, title: a disc at 2 D seen with both eyes}
display: {profile: vive_pro, eye_model: gullstrand_emsley_relaxed, ipd: {mm: 64}}
eyes: stereo
scene:
  - id: disc
    kind: disc
    size_deg: 2
    centre_deg: [3, -2]
    depth: {D: 2}
    surface: {kind: solid, rgb: [1, 1, 1]}
""" + TWO_INTERVAL_TAIL


def test_stereo_disc_at_2D_has_the_exact_disparity(gl_context, tmp_path):
    path = tmp_path / "stereo.yaml"
    path.write_text(STEREO_DISC)
    protocol = load_protocol(path)
    row = compile_schedule(protocol, 0).iloc[0].to_dict()
    # the world point: 0.5 m (2 D) along (3, -2) deg from the head origin, midway between the eyes
    direction = direction_from_angles(3.0, -2.0)
    world_centre = direction * (0.5 / -direction[2])
    fixation = world_centre  # both eyes converge on the disc
    measured, exact = {}, {}
    with Renderer(Scene(()), SETTINGS, ctx=gl_context) as renderer:
        for eye in ("left", "right"):
            centre = np.array([(-0.5 if eye == "left" else 0.5) * IPD_M, 0.0, 0.0])
            scene = build_scene(protocol, row, 0.0, centre, interval=1)
            renderer.set_scene(Scene(scene.primitives, background=(0.0, 0.0, 0.0)))
            for mode in ("conventional", "ocular"):
                full = make_eye_camera(VIVE_PRO, eye, fixation, IPD_M, NC_M, mode)
                px = project_points_px(full, [world_centre])[0]
                x0, y0 = int(px[0]) - 24, int(px[1]) - 24
                renderer.render(crop_camera(full, x0, y0, 48, 48))
                area, cx, cy = _coverage_centroid(renderer.image(eye)[..., 0])
                measured[eye, mode] = (x0 + cx, y0 + cy)
                exact[eye, mode] = tuple(px)
    for mode in ("conventional", "ocular"):
        disparity = measured["left", mode][0] - measured["right", mode][0]
        exact_disparity = exact["left", mode][0] - exact["right", mode][0]
        assert abs(exact_disparity) > 10.0  # 64 mm at 0.5 m: several degrees
        assert disparity == pytest.approx(exact_disparity, abs=0.01), mode
        for eye in ("left", "right"):
            assert np.allclose(measured[eye, mode], exact[eye, mode], atol=0.01), (eye, mode)


def test_stereo_scene_is_the_same_for_both_eyes(tmp_path):
    path = tmp_path / "stereo.yaml"
    path.write_text(STEREO_DISC)
    protocol = load_protocol(path)
    row = compile_schedule(protocol, 0).iloc[0].to_dict()
    left = build_scene(protocol, row, 0.0, [-0.032, 0.0, 0.0])
    right = build_scene(protocol, row, 0.0, [0.032, 0.0, 0.0])
    assert left == right


def test_far_finite_surface_is_not_clipped_by_the_cameras_far_plane(gl_context):
    """A disc 500 m away (0.002 D) lies beyond the cameras' 100 m far plane; the renderer raises the
    far clip to the scene, so it is drawn with its exact area."""
    from psyop.rendering.exact import projected_disc

    disc = frontoparallel_disc(500.0, 2.0, Solid((1.0, 0.0, 0.0)), origin_m=RIGHT_C, name="far")
    cam = _camera("right", "ocular", (5.0, 0.0))
    ellipse = projected_disc(cam, disc)
    crop = _crop(cam, ellipse.centre_px, 24)
    with Renderer(Scene((disc,)), SETTINGS, ctx=gl_context) as renderer:
        renderer.render(crop)
        img = renderer.image()
    area = _coverage_centroid(img[..., 0] - img[..., 1])[0]
    assert area == pytest.approx(math.pi * ellipse.radii_px[0] * ellipse.radii_px[1], rel=0.005)


def test_rotated_border_at_optical_infinity_stays_at_infinity():
    """An oriented sinusoidal border whose far surface is at 0 D: rotating its axes keeps it a
    direction set (it was rebuilt as a 1 m surface)."""
    protocol = load_protocol(PROTOCOLS / "ordinal.yaml")
    item = protocol.scene[0].model_copy(update={"orientation_deg": 90,
                                                "far_depth": protocol.scene[0].far_depth.model_copy(update={"D": 0})})
    protocol = protocol.model_copy(update={"scene": [item, *protocol.scene[1:]]})
    row = compile_schedule(load_protocol(PROTOCOLS / "ordinal.yaml"), 0).iloc[0].to_dict()
    far = next(p for p in build_scene(protocol, row, 0.0, RIGHT_C).primitives if p.name == "surfaces_far")
    assert far.at_infinity and far.half_u_m[0] == pytest.approx(0.0, abs=1e-12)
