"""Eccentricity and meridian of a placement, and the fixation path's radius and speed, as factor levels
(issue 18). Checked in rendered frames against the exact geometry of the documented angles
(docs/optics.md, "Angles"; docs/protocols.md, "Sizes, contrasts, positions and fixation paths as factors"), not in the schedule;
and the simulated pursuit of a session follows the path each trial draws."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from psyop.errors import UserError
from psyop.optics.angles import circle_angular_speed_deg_s, polar_direction
from psyop.optics.camera import make_eye_camera
from psyop.optics.display import VIVE_PRO
from psyop.protocol import parse_protocol
from psyop.schedule import compile_schedule
from psyop.session.plan import compile_plan
from psyop.stimulus import build_scene

from tests.rendering.angle_measure import angle_deg, centre_direction, render_coverage

IPD_M = 0.064
NC_M = 0.0076916
RIGHT_CENTRE_M = np.array([IPD_M / 2.0, 0.0, 0.0])
AHEAD = np.array([0.0, 0.0, -1.0])
BLACK = (0.0, 0.0, 0.0)

PROTOCOL = """psyop_protocol: 1
study: {name: placed_polar, title: a disc placed by eccentricity and meridian and a path by radius and speed}
display: {profile: vive_pro, eye_model: gullstrand_emsley_relaxed, ipd: {mm: 64}}
eyes: right
scene:
  - id: patch
    kind: disc
    size_deg: 2
    depth: {D: 1}
    centre_deg: {eccentricity_deg: {factor: eccentricity_deg}, meridian_deg: {factor: meridian_deg}}
    surface: {kind: solid, rgb: [1, 1, 1]}
  - id: fixation
    kind: fixation_target
    size_deg: 0.5
    depth: {D: 1}
    rgb: [1, 0, 0]
    centre_rgb: [1, 0, 0]
    path: {kind: circle, eccentricity_deg: {factor: radius_deg}, speed_deg_s: {factor: speed_deg_s},
           start: 0, direction: counterclockwise}
trial:
  phases:
    - {kind: interval, duration_s: 1}
    - {kind: interval, duration_s: 1}
    - {kind: response, expected_s: 1}
design:
  factors:
    eccentricity_deg: {levels: [6, 30]}
    meridian_deg: {levels: [45, 200]}
    radius_deg: {levels: [8, 35]}
    speed_deg_s: {levels: [40, 120]}
    level_D: {levels: [0, 0.5]}
  repetitions: 1
  randomisation: {kind: sequential}
response:
  kind: two_interval
  test: {mode: ocular}
  reference: {mode: conventional}
  level_factor: level_D
"""


def _camera():
    """The right eye's conventional camera (centre of projection at its centre of rotation, head-fixed)."""
    return make_eye_camera(VIVE_PRO, "right", RIGHT_CENTRE_M + AHEAD, IPD_M, NC_M, "conventional")


def _measured_direction(gl_context, protocol, row, time_s: float, name: str) -> np.ndarray:
    """Direction from the eye's centre of the rendered primitive ``name`` (its coverage's centre)."""
    scene = build_scene(protocol, row, time_s, RIGHT_CENTRE_M, interval=1, show=[name.split("_")[0]], background=BLACK)
    prim = next(p for p in scene.primitives if p.name == name)
    coverage, crop = render_coverage(gl_context, _camera(), scene, np.array(prim.centre_m), 40)
    return centre_direction(coverage, crop)


def _rows(protocol, columns):
    schedule = compile_schedule(protocol, 0)
    return {tuple(float(row[c]) for c in columns): row.to_dict() for _, row in schedule.iterrows()}


def test_a_disc_centre_as_eccentricity_and_meridian_levels_lands_on_that_direction(gl_context) -> None:
    """Each (eccentricity, meridian) level pair: the rendered disc's centre is the polar direction
    (eccentricity from straight ahead, meridian counter-clockwise from the right) within 0.02 deg, and the
    four pairs land where their own angles say (not all in one place)."""
    protocol = parse_protocol(PROTOCOL, "placed.yaml")
    rows = _rows(protocol, ("eccentricity_deg", "meridian_deg"))
    assert len(rows) == 4
    measured = {}
    for (ecc, meridian), row in rows.items():
        d = _measured_direction(gl_context, protocol, row, 0.0, "patch")
        measured[(ecc, meridian)] = d
        assert angle_deg(d, polar_direction(ecc, meridian)) < 0.02, (ecc, meridian)
        assert angle_deg(d, AHEAD) == pytest.approx(ecc, abs=0.02)
    # the levels move the disc: any two level pairs land at least 10 deg apart
    keys = list(measured)
    assert min(angle_deg(measured[a], measured[b]) for i, a in enumerate(keys) for b in keys[i + 1:]) > 10.0


def test_the_fixation_path_radius_and_speed_levels_are_drawn_as_documented(gl_context) -> None:
    """Each (radius, speed) level pair: over a quarter turn the rendered target stays at the radius's
    eccentricity within 0.02 deg and its angular speed is speed * sin(radius) within 1 %."""
    protocol = parse_protocol(PROTOCOL, "placed.yaml")
    rows = _rows(protocol, ("radius_deg", "speed_deg_s"))
    assert len(rows) == 4
    frame_s = 1.0 / VIVE_PRO.refresh_hz
    for (radius, speed), row in rows.items():
        step_s = 6 * frame_s
        times = [k * (90.0 / speed) / 3 for k in range(3)]  # three points over a quarter turn
        for t in times:
            a = _measured_direction(gl_context, protocol, row, t, "fixation_outer")
            b = _measured_direction(gl_context, protocol, row, t + step_s, "fixation_outer")
            assert angle_deg(a, AHEAD) == pytest.approx(radius, abs=0.02), (radius, speed, t)
            dphi = math.radians(speed * step_s)
            chord_deg = math.degrees(2.0 * math.asin(math.sin(math.radians(radius)) * math.sin(dphi / 2.0)))
            nominal = circle_angular_speed_deg_s(radius, speed)
            assert angle_deg(a, b) / chord_deg * nominal == pytest.approx(nominal, rel=0.01), (radius, speed, t)
        # polar angle 0 at t = 0 is the centre's local right: the target starts at (radius, meridian 0)
        start = _measured_direction(gl_context, protocol, row, 0.0, "fixation_outer")
        assert angle_deg(start, polar_direction(radius, 0.0)) < 0.02


def test_the_simulated_pursuit_follows_each_trials_path() -> None:
    """The session's gaze plan (plan.fixation, psyop.session.loop) is the path the trial's levels draw: at any
    time the pursued direction is the drawn target's centre direction (exact, the one placement rule)."""
    from psyop.session.gaze.plan import circling_target
    from psyop.session.gaze.sample import angles_to_direction

    protocol = parse_protocol(PROTOCOL, "placed.yaml")
    plan = compile_plan(protocol)
    assert plan.fixation is not None and plan.fixation.target is not None
    assert plan.metadata()["fixation_path"]["eccentricity_deg"] == {"factor": "radius_deg"}
    for (radius, speed), row in _rows(protocol, ("radius_deg", "speed_deg_s")).items():
        path = plan.fixation.for_values(row)
        assert (path.eccentricity_deg, path.speed_deg_s) == (radius, speed)
        target = circling_target(path.eccentricity_deg, path.speed_deg_s, 0.0, path.centre_deg)
        for t in (0.0, 0.3, 0.77):
            scene = build_scene(protocol, row, t, RIGHT_CENTRE_M, interval=1, show=["fixation"])
            outer = next(p for p in scene.primitives if p.name == "fixation_outer")
            drawn = np.array(outer.centre_m) - RIGHT_CENTRE_M
            assert angle_deg(angles_to_direction(*target(t)), drawn) < 1e-9


def test_a_simulated_session_pursues_each_trials_radius(tmp_path: Path) -> None:
    """A whole simulated session: the logged gaze of each trial circles at that trial's radius level (mean
    eccentricity within 2 deg: the simulated tracker adds about 1.2 deg of error)."""
    import pandas as pd

    from psyop.cli import main

    text = PROTOCOL.replace("{levels: [6, 30]}", "{levels: [6]}").replace("{levels: [45, 200]}", "{levels: [45]}") \
        .replace("speed_deg_s: {levels: [40, 120]}", "speed_deg_s: {levels: [90]}") \
        .replace("    level_D: {levels: [0, 0.5]}\n", "").replace("    radius_deg:", "    level_D: {levels: [0, 0.5]}\n    radius_deg:")
    text += "observer: {kind: psychometric_2afc, level_column: level_D, threshold_D: 0.3, width_D: 0.2}\n"
    path = tmp_path / "placed.yaml"
    path.write_text(text)
    data = tmp_path / "data"
    # sequential order: trials 0 and 1 (the ones whose frames the log keeps) have radius 8 and 35
    assert main(["simulate", "--protocols", str(path), "--participants", "1", "--data", str(data), "--jobs", "1"]) == 0
    frames = pd.read_parquet(next(data.rglob("frames.parquet")))
    trials = pd.read_parquet(next(data.rglob("trials.parquet")))
    frames = frames[frames["phase"].astype(str).str.startswith("interval") & frames["gaze_valid"]]
    gaze = frames[["fixation_x_m", "fixation_y_m", "fixation_z_m"]].to_numpy() - RIGHT_CENTRE_M
    ecc = np.degrees(np.arccos(-gaze[:, 2] / np.linalg.norm(gaze, axis=1)))
    by_trial = pd.Series(ecc, index=frames["trial"].to_numpy()).groupby(level=0).mean()
    radius = trials.set_index("trial")["radius_deg"]
    assert set(radius.unique()) == {8.0, 35.0}
    assert set(radius[by_trial.index].unique()) == {8.0, 35.0}
    for trial, mean_ecc in by_trial.items():
        assert mean_ecc == pytest.approx(radius[trial], abs=2.0), trial


def test_levels_outside_a_fields_range_and_unused_factors_are_refused() -> None:
    with pytest.raises(UserError, match=r"eccentricity_deg = 95\.0 does not fit this field"):
        parse_protocol(PROTOCOL.replace("{levels: [6, 30]}", "{levels: [6, 95]}"), "p.yaml")
    with pytest.raises(UserError, match=r"speed_deg_s = 0\.0 does not fit this field"):
        parse_protocol(PROTOCOL.replace("{levels: [40, 120]}", "{levels: [0, 120]}"), "p.yaml")
    with pytest.raises(UserError, match="leaves the forward field") as info:
        parse_protocol(PROTOCOL.replace("{levels: [8, 35]}", "{levels: [8, 89.9]}"), "p.yaml")
    assert info.value.location.startswith("p.yaml:")
    # a radius factor nothing reads any more (the path is fixed): refused at its line
    text = PROTOCOL.replace("eccentricity_deg: {factor: radius_deg}", "eccentricity_deg: 16")
    with pytest.raises(UserError, match="factor 'radius_deg' is used by nothing") as info:
        parse_protocol(text, "p.yaml")
    line = int(info.value.location.split(":")[1])
    assert "radius_deg: {levels" in text.splitlines()[line - 1]
    with pytest.raises(UserError, match="'meridan_deg' is not a factor"):
        parse_protocol(PROTOCOL.replace("{factor: meridian_deg}", "{factor: meridan_deg}"), "p.yaml")


def test_an_adaptive_eccentricity_is_rendered_at_the_level_given(tmp_path: Path) -> None:
    """An adaptive level factor on the disc's eccentricity: validation checks the procedure's range against the
    field, and ``psyop render --level`` draws the disc at that eccentricity (centroid of the rendered disc on
    the projection of the polar direction, 0.5 px)."""
    import matplotlib.image as mpimg

    from psyop.cli import main
    from psyop.protocol.display import resolve_display_profile
    from psyop.rendering.camera_math import project_points_px

    text = PROTOCOL.replace("    eccentricity_deg: {levels: [6, 30]}\n", "") \
        .replace("    level_D: {levels: [0, 0.5]}\n",
                 "    eccentricity_deg: {adaptive: {procedure: staircase, start: 20, min: 2, max: 40, "
                 "step_sizes: [4, 2, 1]}}\n") \
        .replace("level_factor: level_D", "level_factor: eccentricity_deg")
    path = tmp_path / "adaptive.yaml"
    path.write_text(text)
    protocol = parse_protocol(text, str(path))
    with pytest.raises(UserError, match="does not fit this field"):
        parse_protocol(text.replace("max: 40", "max: 95"), "p.yaml")
    display = resolve_display_profile(protocol.display)
    camera = make_eye_camera(display, "right", RIGHT_CENTRE_M + AHEAD, IPD_M, NC_M, "conventional")
    row = compile_schedule(protocol, 0).iloc[0]
    for level in (8.0, 25.0):
        out = tmp_path / f"e{level:g}.png"
        assert main(["render", str(path), "--trial", "0", "--interval", str(int(row["correct_interval"])),
                     "--level", str(level), "--mode", "conventional", "--antialiasing", "none", "--out", str(out)]) == 0
        image = (mpimg.imread(out)[..., :3] * 255).round()
        ys, xs = np.nonzero(np.all(image > 250, axis=-1))
        expected = project_points_px(camera, [RIGHT_CENTRE_M + polar_direction(level, float(row["meridian_deg"]))])[0]
        assert abs(xs.mean() + 0.5 - expected[0]) < 0.5 and abs(ys.mean() + 0.5 - expected[1]) < 0.5, level
