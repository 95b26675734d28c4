"""Camera matrices against an independent ray-cast through the display rectangle."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from psyop.optics.camera import make_eye_camera, project_to_pixels
from psyop.optics.display import DisplayProfile, VIVE_PRO
from psyop.optics.nodal import fixation_at_infinity, paper_eye_matrix
from optics_raycast import nodal_reference, raycast_direction, raycast_pixel

EYES = st.sampled_from(["left", "right"])
MODES = st.sampled_from(["conventional", "ocular", "reversed"])
IPD = st.floats(0.050, 0.078)
NC = st.one_of(st.sampled_from([0.0076916, 0.0075906, 0.0091976]), st.floats(0.004, 0.010))
DISTANCE_D = st.one_of(st.just(math.inf), st.floats(0.3, 20.0))


@st.composite
def displays(draw):
    """Vive Pro or an asymmetric random frustum, at a finite or infinite image distance."""
    d_m = draw(DISTANCE_D)
    if draw(st.booleans()):
        base = VIVE_PRO
        return DisplayProfile("vive", base.width_px, base.height_px, 90.0, base.tan_left, base.tan_right,
                              base.tan_bottom, base.tan_top, d_m)
    l = -draw(st.floats(0.3, 1.6))
    r = draw(st.floats(0.3, 1.6))
    b = -draw(st.floats(0.3, 1.6))
    t = draw(st.floats(0.3, 1.6))
    return DisplayProfile("random", draw(st.integers(64, 2048)), draw(st.integers(64, 2048)), 90.0, l, r, b, t, d_m)


@st.composite
def fixations(draw):
    """(fixation argument, is_at_infinity, point or direction): eccentricity 0-40 deg."""
    ecc = math.radians(draw(st.floats(0.0, 40.0)))
    az = math.radians(draw(st.floats(0.0, 360.0)))
    direction = np.array([math.sin(ecc) * math.cos(az), math.sin(ecc) * math.sin(az), -math.cos(ecc)])
    dist = draw(st.one_of(st.just(math.inf), st.floats(0.1, 1e4)))
    if math.isinf(dist):
        return fixation_at_infinity(direction), True, direction
    return dist * direction, False, dist * direction


@st.composite
def world_points(draw):
    """A point in front of the eye (0.05 m to 1 km), inside or outside the frustum."""
    tx = draw(st.floats(-2.0, 2.0))
    ty = draw(st.floats(-2.0, 2.0))
    z = draw(st.floats(0.05, 1000.0))
    return np.array([tx * z, ty * z, -z])


def _expected_cop(eye, ipd, nc, mode, fixation):
    fix_arg, at_inf, vec = fixation
    centre = np.array([(-0.5 if eye == "left" else 0.5) * ipd, 0.0, 0.0])
    n_ref = nc * vec / np.linalg.norm(vec) if at_inf else nodal_reference(vec, centre, nc)
    offset = {"conventional": np.zeros(3), "ocular": n_ref, "reversed": n_ref * np.array([-1, -1, 1])}[mode]
    return centre, centre + offset


@settings(max_examples=300)
@given(displays(), EYES, MODES, IPD, NC, fixations(), world_points())
def test_projection_matches_raycast(display, eye, mode, ipd, nc, fixation, point):
    cam = make_eye_camera(display, eye, fixation[0], ipd, nc, mode, near_m=0.01, far_m=1e4)
    centre, cop = _expected_cop(eye, ipd, nc, mode, fixation)
    assert cam.valid
    np.testing.assert_allclose(cam.centre_of_projection_m, cop, rtol=0, atol=1e-15)
    point = point + centre  # in front of this eye
    tangents = display.frustum_tangents(eye)
    expected = raycast_pixel(point, cop, tangents, centre, display.d_m, display.width_px, display.height_px)
    # the full pipeline as the renderer does it: view, projection, divide, viewport
    clip = cam.projection @ cam.view @ np.append(point, 1.0)
    ndc = clip[:3] / clip[3]
    via_matrices = np.array([(ndc[0] + 1) / 2 * cam.width_px, (1 - ndc[1]) / 2 * cam.height_px])
    np.testing.assert_allclose(via_matrices, expected, rtol=0, atol=1e-6)
    np.testing.assert_allclose(project_to_pixels(cam, point[None])[0], expected, rtol=0, atol=1e-6)


@settings(max_examples=200)
@given(displays(), EYES, MODES, IPD, NC, fixations(), st.floats(-0.5, 1.5), st.floats(-0.5, 1.5))
def test_pixel_to_ray_matches_raycast(display, eye, mode, ipd, nc, fixation, u, v):
    cam = make_eye_camera(display, eye, fixation[0], ipd, nc, mode)
    centre, cop = _expected_cop(eye, ipd, nc, mode, fixation)
    direction = cam.pixel_to_ray @ np.array([u, v, 1.0])
    unit = direction / np.linalg.norm(direction)
    expected = raycast_direction(u, v, cop, display.frustum_tangents(eye), centre, display.d_m)
    np.testing.assert_allclose(unit, expected, rtol=0, atol=1e-12)
    # and back: a point along that ray projects to (u W, v H)
    point = cop + 2.0 * unit
    np.testing.assert_allclose(project_to_pixels(cam, point[None])[0],
                               [u * cam.width_px, v * cam.height_px], rtol=0, atol=1e-6)


def test_view_is_paper_eye_matrix_in_ocular_mode():
    fixation = np.array([0.2, -0.1, -0.6])
    for eye, sign in (("left", -1.0), ("right", 1.0)):
        cam = make_eye_camera(VIVE_PRO, eye, fixation, 0.064, 0.0076916, "ocular")
        centre = np.array([sign * 0.032, 0.0, 0.0])
        n = nodal_reference(fixation, centre, 0.0076916)
        np.testing.assert_allclose(cam.view, paper_eye_matrix(eye, 0.064, n), atol=1e-15)


def test_far_points_fixed_and_near_points_move_with_gaze_at_infinity():
    """d = inf: a point at 1e7 m stays put across modes and gazes; a 1 m point moves ~NC sin e."""
    far = np.array([[0.3e7, 0.1e7, -1e7]])
    near = np.array([[0.032, 0.0, -1.0]])
    gaze = fixation_at_infinity([math.sin(math.radians(15)), 0, -math.cos(math.radians(15))])
    ref = make_eye_camera(VIVE_PRO, "right", [0.032, 0, -1.0], 0.064, 0.0076916, "conventional")
    for mode in ("ocular", "reversed"):
        cam = make_eye_camera(VIVE_PRO, "right", gaze, 0.064, 0.0076916, mode)
        np.testing.assert_allclose(project_to_pixels(cam, far), project_to_pixels(ref, far), atol=1e-3)
    ocular = make_eye_camera(VIVE_PRO, "right", gaze, 0.064, 0.0076916, "ocular")
    reversed_ = make_eye_camera(VIVE_PRO, "right", gaze, 0.064, 0.0076916, "reversed")
    shift_ocular = project_to_pixels(ocular, near) - project_to_pixels(ref, near)
    shift_reversed = project_to_pixels(reversed_, near) - project_to_pixels(ref, near)
    # reversed mode negates the lateral shift exactly (same Nz, opposite Nx, Ny)
    np.testing.assert_allclose(shift_reversed, -shift_ocular, atol=1e-9)
    # camera moves right by NC sin 15 deg, so the 1 m point moves left by about that angle
    px_per_tan = VIVE_PRO.width_px / (VIVE_PRO.tan_right - VIVE_PRO.tan_left)
    expected = -0.0076916 * math.sin(math.radians(15)) / (1.0 - 0.0076916 * math.cos(math.radians(15))) * px_per_tan
    assert math.isclose(shift_ocular[0, 0], expected, rel_tol=1e-9)
    assert abs(shift_ocular[0, 0]) > 0.5  # about half a pixel at 1 D: the paper's regime


def test_conventional_camera_ignores_gaze_and_arrays_are_read_only():
    a = make_eye_camera(VIVE_PRO, "left", [0.5, 0.2, -0.4], 0.064, 0.0076916, "conventional")
    b = make_eye_camera(VIVE_PRO, "left", [-0.5, 0.0, -3.0], 0.064, 0.0076916, "conventional")
    np.testing.assert_array_equal(a.projection, b.projection)
    np.testing.assert_array_equal(a.centre_of_projection_m, [-0.032, 0, 0])
    assert a.eye == "left" and a.mode == "conventional" and a.width_px == 1440 and a.height_px == 1600
    assert not a.view.flags.writeable


def test_points_behind_the_camera_project_to_nan():
    cam = make_eye_camera(VIVE_PRO, "right", [0, 0, -1.0], 0.064, 0.0076916, "ocular")
    px = project_to_pixels(cam, [[0.0, 0.0, 1.0], [0.032, 0.0, -2.0]])
    assert np.isnan(px[0]).all() and np.isfinite(px[1]).all()
