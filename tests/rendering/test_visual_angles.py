"""What the angles in a protocol mean, measured in rendered frames (docs/optics.md, "Angles", "Sizes").

Every number here is read off rendered pixels through the camera's ray geometry
(tests/rendering/angle_measure.py), never off the scene description.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from psyop.optics.angles import angle_between_deg, circle_angular_speed_deg_s, polar_direction, polar_to_fick_deg
from psyop.optics.camera import make_eye_camera
from psyop.optics.display import VIVE_PRO
from psyop.protocol import load_protocol
from psyop.protocol.loader import parse_protocol
from psyop.rendering import Scene, Solid
from psyop.rendering.builders import frontoparallel_radial_subtense_deg, placed_primitive
from psyop.rendering.scene import Shape
from psyop.schedule import compile_schedule
from psyop.stimulus import build_scene

from tests.rendering.angle_measure import (
    angle_deg,
    centre_direction,
    render_coverage,
    subtenses_deg,
    tangent_ellipse,
)

REPO = Path(__file__).resolve().parents[2]
IPD_M = 0.063
NC_M = 0.0076916
RIGHT_CENTRE_M = np.array([IPD_M / 2.0, 0.0, 0.0])
AHEAD = np.array([0.0, 0.0, -1.0])
BLACK = (0.0, 0.0, 0.0)


def _conventional_camera():
    """The right eye's conventional camera: centre of projection at the eye's centre of rotation, the
    display's flat image at infinity (its orientation is head-fixed, whatever the gaze)."""
    return make_eye_camera(VIVE_PRO, "right", RIGHT_CENTRE_M + AHEAD, IPD_M, NC_M, "conventional")


def _fixation_directions(gl_context, protocol, row, times_s):
    """Measured direction (from the eye's centre) of the rendered fixation target at each time."""
    camera = _conventional_camera()
    out = []
    for t in times_s:
        scene = build_scene(protocol, row, t, RIGHT_CENTRE_M, interval=1, show=["fixation"], background=BLACK)
        outer = next(p for p in scene.primitives if p.name.endswith("_outer"))
        coverage, crop = render_coverage(gl_context, camera, scene, np.array(outer.centre_m), 12)
        out.append(centre_direction(coverage, crop))
    return np.array(out)


def _protocol_with_path(eccentricity_deg: float):
    text = (REPO / "protocols" / "detection.yaml").read_text()
    assert "eccentricity_deg: 16 " in text
    return parse_protocol(text.replace("eccentricity_deg: 16 ", f"eccentricity_deg: {eccentricity_deg:g} "),
                          "detection_path.yaml", REPO / "protocols")


@pytest.mark.parametrize("eccentricity_deg", [16.0, 40.0])
def test_the_circling_fixation_target_keeps_its_eccentricity_and_speed_in_rendered_frames(gl_context, eccentricity_deg):
    """The shipped detection protocol (16 deg, 90 deg/s: 24.81 deg/s) and the same path at 40 deg: around the
    whole circle the rendered target stays within 0.01 deg of the nominal eccentricity and moves at the
    nominal angular speed to 0.5 %."""
    protocol = load_protocol(REPO / "protocols" / "detection.yaml") if eccentricity_deg == 16.0 else \
        _protocol_with_path(eccentricity_deg)
    row = compile_schedule(protocol, 3).iloc[0].to_dict()
    speed = 90.0
    frame_s = 1.0 / VIVE_PRO.refresh_hz
    step_frames = 10  # speed measured over 10 frames (10 deg of the circle)
    starts = np.arange(0, 360, 10) / speed  # 36 points, the whole circle
    times = np.sort(np.concatenate([starts, starts + step_frames * frame_s]))
    directions = _fixation_directions(gl_context, protocol, row, times)
    eccentricities = np.array([angle_deg(d, AHEAD) for d in directions])
    assert np.max(np.abs(eccentricities - eccentricity_deg)) < 0.01, eccentricities
    nominal_speed = circle_angular_speed_deg_s(eccentricity_deg, speed)
    dphi = math.radians(speed * step_frames * frame_s)
    # the angle between two points dphi apart on the circle (a chord of the small circle)
    chord_deg = math.degrees(2.0 * math.asin(math.sin(math.radians(eccentricity_deg)) * math.sin(dphi / 2.0)))
    by_time = dict(zip(np.round(times, 12), directions))
    speeds = np.array([angle_deg(by_time[round(t, 12)], by_time[round(t + step_frames * frame_s, 12)])
                       / chord_deg * nominal_speed for t in starts])
    assert np.max(np.abs(speeds / nominal_speed - 1.0)) < 0.005, speeds
    if eccentricity_deg == 16.0:
        assert nominal_speed == pytest.approx(24.81, abs=0.005)


CASES = [(e, m) for e in (0.0, 10.0, 20.0, 30.0, 40.0) for m in (0.0, 135.0)] + [(40.0, 90.0), (25.0, 250.0)]


@pytest.mark.parametrize("facing", ["frontoparallel", "eye"])
def test_disc_subtense_matches_its_definition_in_rendered_frames(gl_context, facing):
    """A 4 deg disc at eccentricities up to 40 deg: frontoparallel, its tangential diameter subtends 4 deg and
    its radial one the documented foreshortened angle; eye-facing, it subtends 4 deg radially and
    tangentially; each to 0.5 %, measured in the rendered pixels."""
    size = 4.0
    camera = _conventional_camera()
    worst = 0.0
    for distance_m in (0.5, math.inf):
        for ecc, meridian in CASES:
            az, el = (float(x) for x in polar_to_fick_deg(ecc, meridian))
            disc = placed_primitive(Shape.DISC, distance_m, size, size, Solid((1.0, 1.0, 1.0)), az, el,
                                    RIGHT_CENTRE_M, facing, name="disc")
            around = (np.array(disc.centre_m) if not disc.at_infinity else np.array(disc.centre_m))
            coverage, crop = render_coverage(gl_context, camera, Scene((disc,), background=BLACK), around,
                                             48 if ecc < 35 else 40, at_infinity=disc.at_infinity)
            ellipse = tangent_ellipse(coverage, crop)
            radial, tangential = subtenses_deg(ellipse, facing)
            measured_ecc = angle_deg(centre_direction(coverage, crop), AHEAD)
            if facing == "frontoparallel":
                expected = (frontoparallel_radial_subtense_deg(size, ecc), size)
                assert measured_ecc == pytest.approx(ecc, abs=0.01)  # its centre is where the angles say
            else:
                expected = (size, size)
            errors = (abs(radial / expected[0] - 1.0), abs(tangential / expected[1] - 1.0))
            worst = max(worst, *errors)
            assert max(errors) < 0.005, (distance_m, ecc, meridian, radial, tangential, expected)
    assert worst > 0.0  # a measurement, not an identity


def test_frontoparallel_foreshortening_is_the_documented_amount():
    """docs/optics.md's numbers: 1.5 % at 10 deg, 3.9 % at 16 deg, 13 % at 30 deg (2 deg disc)."""
    shortening = {e: 1.0 - frontoparallel_radial_subtense_deg(2.0, e) / 2.0 for e in (10.0, 16.0, 30.0)}
    assert shortening[10.0] == pytest.approx(0.015, abs=0.0005)
    assert shortening[16.0] == pytest.approx(0.039, abs=0.0005)
    assert shortening[30.0] == pytest.approx(0.134, abs=0.0015)


def test_fick_gaze_of_the_simulated_tracker_follows_the_drawn_target():
    """The simulated pursuit gaze and the drawn target use one path: the same directions at every time."""
    from psyop.session.gaze.plan import circling_target
    from psyop.stimulus.placement import circle_position_deg

    from psyop.optics.angles import fick_direction

    target = circling_target(16.0, -90.0, 37.0, (5.0, -3.0))
    for t in np.linspace(0.0, 4.0, 17):
        a = fick_direction(*target(float(t)))
        b = fick_direction(*circle_position_deg(5.0, -3.0, 16.0, 37.0, -90.0, float(t)))
        assert float(angle_between_deg(a, b)) < 1e-12
        assert float(angle_between_deg(a, fick_direction(5.0, -3.0))) == pytest.approx(16.0, abs=1e-9)


def test_polar_centre_in_a_protocol_is_the_same_direction_as_its_fick_angles():
    text = (REPO / "protocols" / "detection.yaml").read_text()
    needle = "  - id: back\n    kind: disc\n"
    assert needle in text
    polar = text.replace(needle, needle + "    centre_deg: {eccentricity_deg: 12, meridian_deg: 120}\n    facing: eye\n", 1)
    protocol = parse_protocol(polar, "detection_polar.yaml", REPO / "protocols")
    row = compile_schedule(protocol, 1).iloc[0].to_dict()
    back = next(p for p in build_scene(protocol, row, 0.0, RIGHT_CENTRE_M).primitives if p.name == "back")
    direction = np.array(back.centre_m) - RIGHT_CENTRE_M
    assert float(angle_between_deg(direction, polar_direction(12.0, 120.0))) < 1e-9
    # eye-facing: the disc's plane is perpendicular to the line of sight to its centre
    normal = np.cross(back.half_u_m, back.half_v_m)
    assert float(angle_between_deg(normal, direction)) == pytest.approx(0.0, abs=1e-7) or \
        float(angle_between_deg(normal, -direction)) == pytest.approx(0.0, abs=1e-7)
    assert dataclasses.is_dataclass(back)


def test_the_former_tangent_space_path_left_the_nominal_eccentricity():
    """docs/optics.md: the former path, direction (tan(e cos p), tan(e sin p), -1), put a nominal 40 deg at
    37.27 deg 45 deg around the circle (and 16 deg at 15.80 deg): the rendered-frame test above would fail on it."""
    def old(e_deg: float, p_deg: float) -> float:
        p = math.radians(p_deg)
        d = np.array([math.tan(math.radians(e_deg * math.cos(p))), math.tan(math.radians(e_deg * math.sin(p))), -1.0])
        return float(angle_between_deg(d, AHEAD))

    assert old(40.0, 45.0) == pytest.approx(37.27, abs=0.005)
    assert old(16.0, 45.0) == pytest.approx(15.80, abs=0.005)
