"""Analytic parallax and acuity models against the paper's numbers."""

from __future__ import annotations

import math

import numpy as np

from psyop.optics.parallax import (
    bingham_parallax_diopters_rad,
    bingham_parallax_rad,
    minimum_angle_of_resolution_deg,
    ocular_parallax_exact_rad,
    ocular_parallax_small_angle_rad,
    retinal_speed_deg_s,
)

NC = 0.0076916


def test_retinal_speed_of_the_circling_fixation_target():
    assert round(float(retinal_speed_deg_s(16.0, 90.0)), 2) == 24.81


def test_guenter_mar():
    np.testing.assert_allclose(minimum_angle_of_resolution_deg([0.0, 10.0]), [1 / 60, 0.22 + 1 / 60])
    # the Vive Pro pixel (4.58 arcmin) drops below the MAR at 2-3 deg eccentricity (paper)
    crossing = (110 * 60 / 1440 / 60 - 1 / 60) / 0.022
    assert 2.0 < crossing < 3.0
    assert minimum_angle_of_resolution_deg(crossing) * 60 == np.float64(110 * 60 / 1440) or math.isclose(
        float(minimum_angle_of_resolution_deg(crossing)) * 60, 110 * 60 / 1440)


def test_exact_parallax_against_independent_geometry_and_bingham_form():
    rng = np.random.default_rng(11)
    ecc = rng.uniform(0, 60, 50)
    near = rng.uniform(0.5, 10, 50)
    far = near * rng.uniform(0, 1, 50)
    exact = ocular_parallax_exact_rad(ecc, near, far, NC)
    for e, n_d, f_d, got in zip(ecc, near, far, exact):
        nodal = NC * np.array([math.sin(math.radians(e)), 0.0, -math.cos(math.radians(e))])
        a = np.array([0, 0, -1 / n_d]) - nodal
        b = np.array([0, 0, -1 / f_d]) - nodal if f_d > 0 else np.array([0, 0, -1.0])
        ref = math.acos(min(1.0, a @ b / np.linalg.norm(a) / np.linalg.norm(b)))
        assert math.isclose(got, ref, rel_tol=1e-6, abs_tol=1e-9)
    np.testing.assert_allclose(bingham_parallax_diopters_rad(far, near - far, 15.0, NC),
                               ocular_parallax_exact_rad(15.0, near, far, NC), rtol=1e-10, atol=1e-15)
    assert ocular_parallax_exact_rad(0.0, 3.0, 0.0, NC) == 0.0
    assert np.all(np.diff(ocular_parallax_exact_rad(np.linspace(0, 40, 20), 2.0, 0.0, NC)) > 0)


def test_small_angle_approximation_close_to_exact():
    ecc = np.linspace(1, 40, 40)
    for near_D in (0.5, 1.0, 2.0, 3.0):
        exact = ocular_parallax_exact_rad(ecc, near_D, 0.0, NC)
        approx = ocular_parallax_small_angle_rad(ecc, near_D, 0.0, NC)
        rel = np.abs(approx - exact) / exact
        assert rel.max() < NC * near_D * 1.2  # first-order error ~ NC * D (2.8 % at 3 D)
        assert rel.max() > 0  # they are genuinely different models


def _r_squared(x, y):
    coef = np.polyfit(x, y, 1)
    resid = y - np.polyval(coef, x)
    return 1 - resid @ resid / ((y - y.mean()) @ (y - y.mean())), np.abs(resid).max()


def test_parallax_linear_in_diopters_not_metres():
    """Supplement: Bingham's model, 15 deg rotation, back surface at 1, 2, 3 D."""
    for back_D in (1.0, 2.0, 3.0):
        back_m = 1.0 / back_D
        sep_D = np.linspace(0.0, 2.0, 60)  # front surface 0 to 2 D nearer
        front_m = 1.0 / (back_D + sep_D)
        sep_m = back_m - front_m
        arcmin = np.degrees(bingham_parallax_rad(back_m, front_m, 15.0, NC)) * 60
        r2_D, resid_D = _r_squared(sep_D, arcmin)
        r2_m, resid_m = _r_squared(sep_m, arcmin)
        assert r2_D > 0.99995 and resid_D < 0.005 * arcmin.max()
        assert r2_m < 0.99 and resid_m > 0.05 * arcmin.max()
        # slope in diopters is NC sin 15 deg to first order (next term ~ 2 NC D: 6 % at 4 D)
        slope = np.polyfit(sep_D, np.radians(arcmin / 60), 1)[0]
        assert math.isclose(slope, NC * math.sin(math.radians(15)), rel_tol=0.1)
    # infinite back surface works too
    assert bingham_parallax_diopters_rad(0.0, 1.0) > 0
