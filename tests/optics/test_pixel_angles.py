"""Pixel angles of a display profile (docs/optics.md, "Pixel angles"), and the numbers the docs quote."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from psyop.cli import main
from psyop.optics.angles import polar_direction
from psyop.optics.camera import make_eye_camera, project_to_pixels
from psyop.optics.display import VIVE_PRO, DisplayProfile
from psyop.optics.pixels import pixel_angle, pixel_angles

REPO = Path(__file__).resolve().parents[2]


def _width_arcmin(t0: float, t1: float) -> float:
    """The angle between two rays on the horizontal meridian at tangents t0 and t1."""
    return math.degrees(math.atan(t1) - math.atan(t0)) * 60.0


def test_vive_pro_centre_and_edge_pixels():
    facts = pixel_angles(VIVE_PRO)
    step = 2.0 * math.tan(math.radians(55.0)) / 1440
    assert facts.centre.width_arcmin == pytest.approx(_width_arcmin(0.0, step), rel=1e-5)  # row 800 is half a pixel off
    assert facts.right.width_arcmin == pytest.approx(_width_arcmin(math.tan(math.radians(55.0)) - step,
                                                                   math.tan(math.radians(55.0))), rel=1e-5)
    assert round(facts.centre.width_arcmin, 2) == 6.82
    assert round(facts.right.width_arcmin, 2) == round(facts.left.width_arcmin, 2) == 2.25
    assert round(facts.average_width_arcmin, 2) == 4.58
    # square pixels on the axis; along an edge the pixel is shorter across (1/(1+t^2)) than along (1/sqrt(1+t^2))
    assert facts.centre.height_arcmin == pytest.approx(facts.centre.width_arcmin, rel=1e-9)
    assert facts.right.height_arcmin == pytest.approx(facts.centre.height_arcmin * math.cos(math.radians(55.0)), rel=1e-3)


def test_asymmetric_profile_centre_pixel_is_the_axis_pixel_and_left_eye_mirrors():
    profile = DisplayProfile("asym", 1000, 800, 90.0, -1.0, 0.5, -0.6, 0.8)
    right = pixel_angles(profile, "right")
    assert (right.centre.column, right.centre.row) == (666, 457)  # tangent 0 lies in that pixel
    left = pixel_angles(profile, "left")
    assert left.left.width_arcmin == pytest.approx(right.right.width_arcmin, rel=1e-12)
    assert right.left.width_arcmin < right.right.width_arcmin  # the wider side has the smaller pixels
    with pytest.raises(ValueError):
        pixel_angle(profile, 1000, 0)


def test_psyop_show_prints_the_pixel_angles(capsys):
    assert main(["show", str(REPO / "protocols" / "detection.yaml")]) == 0
    out = capsys.readouterr().out
    assert "centre  pixel (720, 800): 6.82 x 6.82 arcmin" in out
    assert "right   pixel (1439, 800): 2.25 x 3.91 arcmin" in out
    assert "average across a row: 4.58 arcmin" in out


def test_threshold_edge_shift_at_the_display_centre_is_0_37_to_0_38_px():
    """docs/rendering.md: 0.36 D at 16 deg gaze moves the detection disc's edge (1 deg from the axis) by
    0.37-0.38 px, not half a pixel (half a pixel holds only at the 4.58 arcmin/px average)."""
    centre = np.array([0.0315, 0.0, 0.0])
    shifts = []
    for back_D in (1.0, 2.0, 3.0):
        camera = make_eye_camera(VIVE_PRO, "right", centre + polar_direction(16.0, 0.0), 0.063, 0.0076916, "ocular")
        edge = polar_direction(1.0, 0.0)
        points = np.array([centre + edge / -edge[2] / back_D, centre + edge / -edge[2] / (back_D + 0.36)])
        px = project_to_pixels(camera, points)
        shifts.append(float(np.linalg.norm(px[0] - px[1])))
    assert 0.365 < min(shifts) and max(shifts) < 0.385, shifts
