"""The paper's frustum equations (5)-(6) against the exact ray geometry.

Derivation (docs/optics.md): with the camera at C + N (eye matrix E translates by -N), the
image rectangle's left edge seen from the camera has tangent (l - Nx/d) / (1 + Nz/d). The
paper's near-plane value is (z_near + Nz) (l + Nx/d) / (1 + Nz/d). So:
  * the factor (z_near + Nz) is the near plane's distance from N when z_near is measured from
    C; the projection matrix must then use near = z_near + Nz (using z_near scales the image
    by (z_near + Nz) / z_near);
  * the +Nx/d, +Ny/d terms have the wrong sign: the tangents differ by 2 Nx / (d + Nz), which
    vanishes only for d = inf (the paper's assumption).
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from optics_raycast import raycast_pixel

from psyop.optics.camera import clip_to_pixels, off_axis_tangents, paper_frustum_near_plane
from psyop.optics.display import VIVE_PRO, DisplayProfile
from psyop.optics.nodal import eye_centre_m

NC = 0.0076916


def _display(d_m):
    v = VIVE_PRO
    return DisplayProfile("vive", v.width_px, v.height_px, 90.0, v.tan_left, v.tan_right, v.tan_bottom, v.tan_top, d_m)


def _nodal(ecc_deg, az_deg):
    e, a = math.radians(ecc_deg), math.radians(az_deg)
    return NC * np.array([math.sin(e) * math.cos(a), math.sin(e) * math.sin(a), -math.cos(e)])


def _glfrustum(l, r, b, t, n, f):
    """The paper's eq. 4 (OpenGL glFrustum), written out from the paper."""
    return np.array([
        [2 * n / (r - l), 0, (r + l) / (r - l), 0],
        [0, 2 * n / (t - b), (t + b) / (t - b), 0],
        [0, 0, -(f + n) / (f - n), -2 * f * n / (f - n)],
        [0, 0, -1, 0],
    ])


def _paper_pixels(display, eye, nodal, z_near, matrix_near, points):
    l, r, b, t = paper_frustum_near_plane(display, eye, nodal, z_near)[0]
    proj = _glfrustum(l, r, b, t, matrix_near, 100.0)
    cop = eye_centre_m(eye, 0.064) + nodal
    eye_space = np.concatenate([points - cop, np.ones((len(points), 1))], axis=1)
    return clip_to_pixels(eye_space @ proj.T, display.width_px, display.height_px)


def _points(eye, n=25):
    rng = np.random.default_rng(3)
    z = rng.uniform(0.2, 5.0, n)
    pts = np.stack([rng.uniform(-1.3, 1.3, n) * z, rng.uniform(-1.5, 1.5, n) * z, -z], axis=1)
    return pts + eye_centre_m(eye, 0.064)


def _raycast(display, eye, nodal, points):
    cop = eye_centre_m(eye, 0.064) + nodal
    return np.array([raycast_pixel(p, cop, display.frustum_tangents(eye), eye_centre_m(eye, 0.064), display.d_m,
                                   display.width_px, display.height_px) for p in points])


@settings(max_examples=60)
@given(st.floats(0.0, 40.0), st.floats(0.0, 360.0), st.sampled_from(["left", "right"]), st.floats(0.02, 1.0))
def test_paper_equations_are_exact_at_infinity_with_near_measured_from_c(ecc, az, eye, z_near):
    display, nodal = _display(math.inf), _nodal(ecc, az)
    pts = _points(eye)
    got = _paper_pixels(display, eye, nodal, z_near, z_near + nodal[2], pts)
    np.testing.assert_allclose(got, _raycast(display, eye, nodal, pts), rtol=0, atol=1e-6)


@settings(max_examples=60)
@given(st.floats(5.0, 40.0), st.floats(0.0, 360.0), st.floats(0.05, 1.0))
def test_paper_equations_with_matrix_near_z_near_magnify_by_exact_factor(ecc, az, z_near):
    """Using z_near itself in the matrix scales every tangent by (z_near + Nz) / z_near."""
    display, nodal = _display(math.inf), _nodal(ecc, az)
    paper_tan = paper_frustum_near_plane(display, "right", nodal, z_near)[0] / z_near
    exact_tan = off_axis_tangents(display.frustum_tangents("right"), nodal, display.d_m)[0]
    np.testing.assert_allclose(paper_tan, exact_tan * (z_near + nodal[2]) / z_near, rtol=1e-12)
    pts = _points("right")
    err = np.abs(_paper_pixels(display, "right", nodal, z_near, z_near, pts) - _raycast(display, "right", nodal, pts))
    assert err.max() > 0.01  # a visible error, not rounding


@settings(max_examples=60)
@given(st.floats(5.0, 40.0), st.floats(0.0, 360.0), st.floats(0.3, 10.0), st.sampled_from(["left", "right"]))
def test_paper_equations_at_finite_distance_have_the_nodal_shift_sign_flipped(ecc, az, d_m, eye):
    display, nodal = _display(d_m), _nodal(ecc, az)
    z_near = 0.1
    paper_tan = paper_frustum_near_plane(display, eye, nodal, z_near)[0] / (z_near + nodal[2])
    exact_tan = off_axis_tangents(display.frustum_tangents(eye), nodal, d_m)[0]
    shift = 2.0 / (d_m + nodal[2]) * np.array([nodal[0], nodal[0], nodal[1], nodal[1]])
    np.testing.assert_allclose(paper_tan - exact_tan, shift, rtol=1e-9, atol=1e-15)
    # flipping the sign of (Nx, Ny) in eqs. 5-6 makes them exact for any d
    flipped = nodal * np.array([-1.0, -1.0, 1.0])
    fixed_tan = paper_frustum_near_plane(display, eye, flipped, z_near)[0] / (z_near + nodal[2])
    np.testing.assert_allclose(fixed_tan, exact_tan, rtol=1e-12, atol=1e-15)


def test_size_of_the_paper_equation_errors_on_the_vive_pro():
    """Worked numbers quoted in docs/optics.md (15 deg gaze to the right)."""
    nodal = _nodal(15.0, 0.0)
    pts = _points("right", 200)
    at_1m = _display(1.0)
    err_finite = np.abs(_paper_pixels(at_1m, "right", nodal, 0.1, 0.1 + nodal[2], pts) - _raycast(at_1m, "right", nodal, pts))
    inf = _display(math.inf)
    err_near = np.abs(_paper_pixels(inf, "right", nodal, 0.1, 0.1, pts) - _raycast(inf, "right", nodal, pts))
    px_per_tan = at_1m.width_px / (at_1m.tan_right - at_1m.tan_left)
    # a uniform shift of 2 Nx / (d + Nz) in tangent = 2 Nx / d of the fixed image width: 2.0 px at d = 1 m
    np.testing.assert_allclose(err_finite[:, 0], 2 * nodal[0] / 1.0 * px_per_tan, rtol=0, atol=1e-6)
    assert 1.9 < err_finite[:, 0].max() < 2.1
    # magnification (0.1 + Nz) / 0.1 = 0.9257: up to 7.4 % of the distance from the image centre
    centre_px = inf.width_px / 2
    assert err_near[:, 0].max() > 0.07 * np.abs(_raycast(inf, "right", nodal, pts)[:, 0] - centre_px).max()
    print(f"finite d=1m: {err_finite[:, 0].max():.3f} px; z_near as matrix near: {err_near.max():.1f} px")
