"""Cameras from a runtime's views (psyop.optics.camera.make_view_camera) against the profile path
and against exact ray geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from psyop.optics.camera import ViewGeometry, make_eye_camera, make_view_camera
from psyop.optics.display import DisplayProfile, VIVE_PRO, display_profile_from_mapping

NC = 0.0076916


@pytest.mark.cross_cpu
@pytest.mark.parametrize("eye", ["left", "right"])
@pytest.mark.parametrize("mode", ["conventional", "ocular", "reversed"])
@pytest.mark.parametrize("fixation", [(0.1, -0.05, -0.8), (0.0, 0.0, -1e4, 0.0), (-0.3, 0.2, -0.4)])
def test_an_uncanted_view_equals_the_profile_camera_exactly(eye, mode, fixation):
    ipd = 0.064
    cx = (-0.5 if eye == "left" else 0.5) * ipd
    view = ViewGeometry(eye, (cx, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), VIVE_PRO.frustum_tangents(eye))
    fix = np.array(fixation if len(fixation) == 4 else fixation)
    a = make_eye_camera(VIVE_PRO, eye, fix, ipd, NC, mode)
    b = make_view_camera(view, VIVE_PRO.width_px, VIVE_PRO.height_px, fix, NC, mode)
    for name in ("centre_of_projection_m", "view", "projection", "pixel_to_ray"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.valid == b.valid


def _ray_through(camera, x_px, y_px):
    d = camera.pixel_to_ray @ np.array([x_px / camera.width_px, y_px / camera.height_px, 1.0])
    return d / np.linalg.norm(d)


def test_a_view_off_the_axis_places_the_nodal_point_on_the_gaze_line_from_its_own_centre():
    view = ViewGeometry("left", (-0.031, 0.012, 0.004), (1.0, 0.0, 0.0, 0.0), (-0.9, 0.7, -0.85, 0.8))
    fixation = np.array([0.2, 0.1, -0.6])
    cam = make_view_camera(view, 400, 300, fixation, NC, "ocular")
    c = np.array(view.centre_m)
    u = (fixation - c) / np.linalg.norm(fixation - c)
    np.testing.assert_allclose(cam.centre_of_projection_m, c + NC * u, atol=1e-15)


def test_a_canted_view_rotates_its_rays_exactly():
    yaw = math.radians(10.0)  # the eye's image turned 10 deg outwards (to the left for the left eye)
    q = (math.cos(yaw / 2), 0.0, math.sin(yaw / 2), 0.0)
    view = ViewGeometry("left", (-0.032, 0.0, 0.0), q, (-1.0, 1.0, -1.0, 1.0))
    cam = make_view_camera(view, 200, 200, (0.0, 0.0, -1.0), NC, "conventional")
    centre_ray = _ray_through(cam, 100.0, 100.0)  # the image centre looks along the canted axis
    np.testing.assert_allclose(centre_ray, [-math.sin(yaw), 0.0, -math.cos(yaw)], atol=1e-15)
    edge_ray = _ray_through(cam, 0.0, 100.0)  # left edge: 45 deg left of the canted axis
    np.testing.assert_allclose(edge_ray, [-math.sin(yaw + math.pi / 4), 0.0, -math.cos(yaw + math.pi / 4)], atol=1e-15)
    # the view matrix takes a head-space point on the canted axis to the eye's -z axis
    p = np.array([-0.032 - math.sin(yaw), 0.0, -math.cos(yaw), 1.0])
    np.testing.assert_allclose((cam.view @ p)[:3], [0.0, 0.0, -1.0], atol=1e-15)


def test_a_bad_view_is_refused_with_its_eye_named():
    with pytest.raises(ValueError, match="left eye"):
        ViewGeometry("left", (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (0.5, -0.5, -1.0, 1.0))
    with pytest.raises(ValueError, match="unit quaternion"):
        ViewGeometry("right", (0.0, 0.0, 0.0), (2.0, 0.0, 0.0, 0.0), (-1.0, 1.0, -1.0, 1.0))


def test_a_profile_holds_each_eyes_own_asymmetric_field_of_view():
    p = display_profile_from_mapping({"name": "asym", "width_px": 100, "height_px": 100, "refresh_hz": 90,
                                      "tan_left": -0.9, "tan_right": 1.1, "tan_bottom": -1.0, "tan_top": 0.95,
                                      "left_tangents": [-1.2, 0.8, -1.05, 0.9]})
    assert p.frustum_tangents("right") == (-0.9, 1.1, -1.0, 0.95)
    assert p.frustum_tangents("left") == (-1.2, 0.8, -1.05, 0.9)
    mirrored = DisplayProfile("m", 10, 10, 90.0, -0.9, 1.1, -1.0, 0.95)
    assert mirrored.frustum_tangents("left") == (-1.1, 0.9, -1.0, 0.95)
    with pytest.raises(ValueError, match="left_tangents"):
        DisplayProfile("bad", 10, 10, 90.0, -0.9, 1.1, -1.0, 0.95, left_tangents=(0.5, -0.5, -1.0, 1.0))
