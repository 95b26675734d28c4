"""Sub-pixel accuracy of the ray-cast renderer against exact ray geometry, in rendered pixels."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from psyop.rendering import AntiAliasing, Renderer, RenderSettings, Scene, Solid
from psyop.rendering.builders import detection_stimulus, ordinal_stimulus
from psyop.rendering.camera_math import crop_camera, project_points_px
from psyop.rendering.exact import border_x_px, projected_disc, visible_back_area_px
from psyop.rendering.measure import RIGHT_CENTRE_M as RIGHT_EYE_CENTRE_M
from psyop.rendering.measure import right_eye_camera as gaze_camera

GAZE_AZ_EL_DEG = (16.0 * math.cos(0.7), 16.0 * math.sin(0.7))  # 16 deg eccentricity, oblique


def _crop_around(camera, point_m, half_px: int):
    c = project_points_px(camera, [point_m])[0]
    return crop_camera(camera, int(c[0]) - half_px, int(c[1]) - half_px, 2 * half_px, 2 * half_px)


def _red_area_px(img: np.ndarray) -> float:
    # Front disc and background are grey (R = G = B), the back disc pure red: R - G is the
    # coverage-weighted red fraction of every pixel.
    return float(np.sum(img[..., 0].astype(np.float64) - img[..., 1]))


@pytest.mark.parametrize("back_D", [1.0, 2.0, 3.0])
def test_detection_visible_red_area_matches_circle_overlap(gl_context, back_D):
    worst = 0.0
    back, front = detection_stimulus(back_D, 1.0, origin_m=RIGHT_EYE_CENTRE_M)
    with Renderer(Scene((back, front)), ctx=gl_context) as renderer:
        for rel_D in (0.25, 0.5, 1.0):
            back, front = detection_stimulus(back_D, rel_D, origin_m=RIGHT_EYE_CENTRE_M)
            renderer.set_scene(Scene((back, front)))
            camera = _crop_around(gaze_camera(*GAZE_AZ_EL_DEG, "ocular"), back.centre_m, 24)
            renderer.render(camera)
            measured = _red_area_px(renderer.image())
            expected = visible_back_area_px(camera, back, front)
            assert expected > 3.0  # a crescent of several pixels is really there
            worst = max(worst, abs(measured - expected) / expected)
            # no red outside the back disc's image: everything red lies within its circle
    assert worst < 0.02, f"worst relative red-area error {worst:.4f}"


@pytest.mark.parametrize("mode", ["conventional"])
def test_conventional_mode_hides_the_back_disc(gl_context, mode):
    for back_D in (1.0, 3.0):
        back, front = detection_stimulus(back_D, 1.0, origin_m=RIGHT_EYE_CENTRE_M)
        camera = _crop_around(gaze_camera(*GAZE_AZ_EL_DEG, mode), back.centre_m, 24)
        with Renderer(Scene((back, front)), ctx=gl_context) as renderer:
            renderer.render(camera)
            img = renderer.image()
        assert abs(_red_area_px(img)) < 1e-3
        assert visible_back_area_px(camera, back, front) == pytest.approx(0.0, abs=1e-6)


def test_reversed_mode_matches_geometry_and_over_blending_would_not(gl_context):
    back, front = detection_stimulus(2.0, 0.5, origin_m=RIGHT_EYE_CENTRE_M)
    camera = _crop_around(gaze_camera(*GAZE_AZ_EL_DEG, "reversed"), back.centre_m, 24)
    with Renderer(Scene((back, front)), ctx=gl_context) as renderer:
        renderer.render(camera)
        measured = _red_area_px(renderer.image())
    expected = visible_back_area_px(camera, back, front)
    assert measured == pytest.approx(expected, rel=0.02)


def _ordinal_edge_case(gl_context, antialiasing: AntiAliasing, mode: str = "ocular"):
    rear, front = ordinal_stimulus(0.5, 2.5, "left", origin_m=RIGHT_EYE_CENTRE_M, amplitude_deg=1.0, cycles=3.0,
                                   phase_rad=0.4)
    rear = dataclasses.replace(rear, material=Solid((0.0, 0.0, 0.0)))
    front = dataclasses.replace(front, material=Solid((1.0, 1.0, 1.0)))
    full = gaze_camera(9.0, -5.0, mode)
    centre = project_points_px(full, [front.centre_m])[0]
    x0, y0, w, h = int(centre[0]) - 24, int(centre[1]) - 40, 48, 80
    camera = crop_camera(full, x0, y0, w, h)
    settings = RenderSettings(antialiasing=antialiasing, samples_per_axis=32)
    with Renderer(Scene((rear, front)), settings, ctx=gl_context) as renderer:
        renderer.render(camera)
        img = renderer.image()
    # Front (white) lies left of the border: the row's white coverage is the mean edge x.
    measured = img[..., 1].astype(np.float64).sum(axis=1)
    sub = (np.arange(64) + 0.5) / 64.0
    rows = np.arange(h)[:, None] + sub[None, :]
    expected = border_x_px(camera, front, rows.ravel()).reshape(h, 64).mean(axis=1)
    assert np.all((expected > 2) & (expected < w - 2))  # the border stays inside the window
    return np.abs(measured - expected)


def test_ordinal_border_position_within_0_02_px_of_ray_cast(gl_context):
    errors = _ordinal_edge_case(gl_context, AntiAliasing.ADAPTIVE)
    assert errors.max() < 0.02, f"max edge error {errors.max():.4f} px"


def test_ordinal_border_without_antialiasing_is_visibly_quantised(gl_context):
    # The same measurement is sensitive: one sample per pixel misplaces edges by tenths of a pixel.
    errors = _ordinal_edge_case(gl_context, AntiAliasing.NONE)
    assert errors.max() > 0.1


def test_adaptive_sampling_is_confined_to_edges(gl_context):
    # Work accounting: only pixels whose centre lies within ~1 px of a primitive edge take the
    # 32x32 path; every such pixel lies in a band of +-1.75 px around the two projected rims.
    back, front = detection_stimulus(2.0, 0.5, origin_m=RIGHT_EYE_CENTRE_M)
    camera = _crop_around(gaze_camera(*GAZE_AZ_EL_DEG, "ocular"), back.centre_m, 24)
    with Renderer(Scene((back, front)), ctx=gl_context) as renderer:
        renderer.render(camera)
        n_edge = renderer.edge_pixel_count()
    rims = [projected_disc(camera, disc) for disc in (back, front)]
    band_area = sum(math.pi * ((r.radii_px[0] + 1.75) ** 2 - (r.radii_px[0] - 1.75) ** 2) for r in rims)
    inner_band = sum(math.pi * ((r.radii_px[0] + 0.5) ** 2 - (r.radii_px[0] - 0.5) ** 2) for r in rims)
    assert inner_band * 0.9 < n_edge < band_area
