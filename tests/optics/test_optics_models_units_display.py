"""Eye models (Table 1), units and display profiles."""

from __future__ import annotations

import math

import numpy as np
import pytest

from psyop.optics import units
from psyop.optics.display import VIVE_PRO, DisplayProfile, display_profile_from_mapping, get_display_profile
from psyop.optics.eye_models import (
    DEFAULT_EYE_MODEL,
    EYE_MODELS,
    EyeModel,
    get_eye_model,
    user_eye_model,
)
from psyop.optics.nodal import Eye, RenderingMode, eye_centre_m, parse_mode


def test_table1_and_default_nc():
    expected_vn = {
        "gullstrand_no1_relaxed": (7.078, 7.331),
        "gullstrand_no1_accommodated": (6.533, 6.847),
        "gullstrand_emsley_relaxed": (7.062, 7.363),
        "gullstrand_emsley_accommodated": (6.562, 6.909),
        "emsley_reduced": (5.556, 5.556),
    }
    assert set(EYE_MODELS) == set(expected_vn)
    for name, (vn, vnp) in expected_vn.items():
        model = get_eye_model(name)
        assert (model.vn_mm, model.vn_prime_mm) == (vn, vnp)
        assert math.isclose(model.nc_m, (14.7536 - vn) / 1000, rel_tol=1e-12)
        assert 0.007 <= model.nc_m <= 0.0092  # "7-8 mm in all cases" (Emsley reduced: 9.2 mm)
    assert DEFAULT_EYE_MODEL.name == "gullstrand_emsley_relaxed"
    assert math.isclose(DEFAULT_EYE_MODEL.nc_m * 1000, 7.6916, abs_tol=1e-12)
    # accommodating moves N toward the cornea: NC grows
    assert get_eye_model("gullstrand_emsley_accommodated").nc_m > DEFAULT_EYE_MODEL.nc_m


def test_unknown_eye_model_lists_valid_names_and_user_model_round_trips():
    with pytest.raises(ValueError, match="gullstrand_emsley_relaxed.*emsley_reduced|emsley_reduced"):
        get_eye_model("gullstrand")
    model = user_eye_model(0.0071, name="sub-01")
    assert math.isclose(model.nc_m, 0.0071, rel_tol=1e-12) and model.name == "sub-01"
    for bad in (0.0, -0.001, 0.5, float("nan")):
        with pytest.raises(ValueError):
            user_eye_model(bad)
    with pytest.raises(ValueError):
        EyeModel("bad", vn_mm=20.0, vn_prime_mm=20.0)
    with pytest.raises(Exception):
        DEFAULT_EYE_MODEL.vn_mm = 1.0  # frozen


def test_units():
    assert units.diopters_to_m(0.0) == math.inf and units.m_to_diopters(math.inf) == 0.0
    np.testing.assert_allclose(units.diopters_to_m([0.5, 2.0, 0.0]), [2.0, 0.5, np.inf])
    assert math.isclose(units.m_to_diopters(0.25), 4.0)
    assert math.isclose(units.deg_to_arcmin(1.5), 90.0) and math.isclose(units.arcmin_to_deg(30.0), 0.5)
    assert math.isclose(units.rad_to_deg(units.deg_to_rad(37.0)), 37.0)
    assert math.isclose(units.arcmin_per_px(110.0, 1440), 4.5833333333, rel_tol=1e-9)
    assert round(units.arcmin_per_px(110.0, 1440), 2) == 4.58
    assert math.isclose(units.px_to_arcmin(units.arcmin_to_px(7.0, 110.0, 1440), 110.0, 1440), 7.0)
    assert math.isclose(units.rad_to_arcmin(math.radians(1.0)), 60.0)
    with pytest.raises(ValueError):
        units.arcmin_per_px(110.0, 0)


def test_vive_pro_profile():
    assert (VIVE_PRO.width_px, VIVE_PRO.height_px, VIVE_PRO.refresh_hz) == (1440, 1600, 90.0)
    assert math.isinf(VIVE_PRO.d_m)
    assert math.isclose(VIVE_PRO.horizontal_fov_deg, 110.0, rel_tol=1e-12)
    assert round(VIVE_PRO.arcmin_per_px, 2) == 4.58
    assert math.isclose(VIVE_PRO.frame_period_s * 1000, 11.111, rel_tol=1e-4)
    # aspect-matched: the same tangent per pixel in x and y
    px_x = (VIVE_PRO.tan_right - VIVE_PRO.tan_left) / VIVE_PRO.width_px
    px_y = (VIVE_PRO.tan_top - VIVE_PRO.tan_bottom) / VIVE_PRO.height_px
    assert math.isclose(px_x, px_y, rel_tol=1e-12)
    assert get_display_profile("vive_pro") is VIVE_PRO
    with pytest.raises(ValueError, match="vive_pro"):
        get_display_profile("rift")


def test_left_eye_is_mirrored():
    d = DisplayProfile("asym", 100, 100, 60.0, -1.4, 1.2, -1.5, 1.45)
    assert d.frustum_tangents("right") == (-1.4, 1.2, -1.5, 1.45)
    assert d.frustum_tangents(Eye.LEFT) == (-1.2, 1.4, -1.5, 1.45)
    with pytest.raises(ValueError):
        d.frustum_tangents("middle")


def test_display_profile_from_mapping():
    p = display_profile_from_mapping({"name": "mine", "width_px": 1000, "height_px": 800, "refresh_hz": 120,
                                      "tan_left": -1.0, "tan_right": 1.1, "tan_bottom": -0.9, "tan_top": 0.8,
                                      "d_m": 1.5})
    assert p.tan_right == 1.1 and p.d_m == 1.5
    q = display_profile_from_mapping({"name": "sym", "width_px": 1440, "height_px": 1600, "refresh_hz": 90,
                                      "horizontal_fov_deg": 110, "d_m": "inf"})
    assert math.isclose(q.tan_top, VIVE_PRO.tan_top) and math.isinf(q.d_m)
    r = display_profile_from_mapping({"name": "v", "width_px": 10, "height_px": 10, "refresh_hz": 60,
                                      "horizontal_fov_deg": 90, "vertical_fov_deg": 60, "d_m": None})
    assert math.isclose(r.vertical_fov_deg, 60.0) and math.isinf(r.d_m)
    base = {"name": "b", "width_px": 10, "height_px": 10, "refresh_hz": 60, "horizontal_fov_deg": 90}
    bad = [
        ({**base, "colour": 1}, "unknown key"),
        ({k: v for k, v in base.items() if k != "refresh_hz"}, "missing"),
        ({**base, "width_px": 0}, "width_px"),
        ({**base, "width_px": 10.5}, "width_px"),
        ({**base, "d_m": 0.01}, "d_m"),
        ({**base, "d_m": "far"}, "d_m"),
        ({**base, "horizontal_fov_deg": 200}, "horizontal_fov_deg"),
        ({**base, "tan_left": -1.0}, "either"),
        ({"name": "t", "width_px": 10, "height_px": 10, "refresh_hz": 60, "tan_left": -1.0}, "missing"),
        ({"name": "t", "width_px": 10, "height_px": 10, "refresh_hz": 60, "tan_left": 1.0, "tan_right": -1.0,
          "tan_bottom": -1.0, "tan_top": 1.0}, "tan_left"),
        ([1, 2], "mapping"),
    ]
    for mapping, message in bad:
        with pytest.raises(ValueError, match=message):
            display_profile_from_mapping(mapping)


def test_enums_and_eye_centres():
    assert Eye.LEFT == "left" and str(RenderingMode.REVERSED) == "reversed"
    np.testing.assert_array_equal(eye_centre_m("left", 0.064), [-0.032, 0, 0])
    np.testing.assert_array_equal(eye_centre_m(Eye.RIGHT, 0.064), [0.032, 0, 0])
    with pytest.raises(ValueError, match="conventional"):
        parse_mode("fancy")


def test_make_eye_camera_rejects_bad_configuration():
    from psyop.optics.camera import make_eye_camera

    good = dict(display=VIVE_PRO, eye="left", fixation_m=[0, 0, -1.0], ipd_m=0.064, nc_m=0.0076916, mode="ocular")
    assert make_eye_camera(**good).valid
    for change, message in (
        ({"ipd_m": float("nan")}, "ipd_m"),
        ({"nc_m": 0.5}, "nc_m"),
        ({"near_m": 1.0, "far_m": 0.5}, "near_m"),
        ({"near_m": 0.0}, "near_m"),
        ({"fixation_m": [0.0, -1.0]}, "shape"),
        ({"eye": "cyclops"}, "eye"),
        ({"mode": "inverse"}, "rendering mode"),
    ):
        with pytest.raises(ValueError, match=message):
            make_eye_camera(**{**good, **change})
    with pytest.raises(ValueError, match="horizontal_fov_deg"):
        display_profile_from_mapping({"name": "n", "width_px": 10, "height_px": 10, "refresh_hz": 60,
                                      "horizontal_fov_deg": "wide"})
