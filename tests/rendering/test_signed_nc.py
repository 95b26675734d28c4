"""NC nulling (issue 18, the paper's future work): a signed rendered NC. Each trial is rendered with its
level's sign as the mode (> 0 ocular, 0 conventional, < 0 reversed) and its size as the NC: checked in
rendered frames against the exact visible area of a back disc hidden behind a front disc, for the camera
the level documents, and by the side the sliver shows on."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest

from psyop.cli import main
from psyop.errors import UserError
from psyop.optics.camera import make_eye_camera
from psyop.protocol import load_protocol, parse_protocol
from psyop.protocol.display import resolve_display_profile
from psyop.rendering.builders import direction_from_angles
from psyop.rendering.camera_math import crop_camera, project_points_px
from psyop.rendering.exact import visible_back_area_px
from psyop.schedule import compile_schedule
from psyop.stimulus import build_scene

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "protocols" / "examples" / "nc_calibration.yaml"

TEXT = """psyop_protocol: 1
study: {name: signed_nc, title: signed rendered NC}
display: {profile: vive_pro, eye_model: gullstrand_emsley_relaxed, ipd: {mm: 64},
          rendering_nc: {mm: {factor: nc_mm}, signed: true}}
eyes: right
scene:
  - {id: back, kind: disc, size_deg: 2, depth: {D: 1}, surface: {kind: solid, rgb: [1, 0, 0]}}
  - {id: front, kind: disc, size_deg: 2, depth: {D: 2}, surface: {kind: solid, rgb: [1, 1, 1]}}
trial:
  phases:
    - {kind: interval, duration_s: 1}
    - {kind: response, expected_s: 1}
design:
  factors:
    nc_mm: {levels: [-6, 0, 6, 12]}
  repetitions: 1
  randomisation: {kind: sequential}
response: {kind: with_against, nc_factor: nc_mm}
observer: {kind: nc_nulling, nc_mm: 7.7, width_mm: 3}
"""

MODES = {-6.0: ("reversed", 6.0), 0.0: ("conventional", 7.6916), 6.0: ("ocular", 6.0), 12.0: ("ocular", 12.0)}


def test_each_signed_level_is_rendered_with_its_mode_and_nc(tmp_path: Path) -> None:
    path = tmp_path / "signed.yaml"
    path.write_text(TEXT)
    protocol = parse_protocol(TEXT, str(path))
    schedule = compile_schedule(protocol, 0)
    display = resolve_display_profile(protocol.display)
    centre = np.array([0.032, 0.0, 0.0])
    fixation = centre + direction_from_angles(16.0, 0.0) * 0.5  # gaze 16 deg to the right, at 0.5 m
    areas, sides = {}, {}
    for _, row in schedule.iterrows():
        level = float(row["nc_mm"])
        mode, nc_mm = MODES[level]
        assert row["mode_interval1"] == mode and row["rendered_nc_mm"] == level
        exact_camera = make_eye_camera(display, "right", fixation, 0.064, nc_mm / 1000.0, mode)
        scene = build_scene(protocol, row.to_dict(), 0.0, centre, interval=1)
        back, front = (next(p for p in scene.primitives if p.name == n) for n in ("back", "front"))
        c = project_points_px(exact_camera, [back.centre_m])[0]
        x0, y0 = int(c[0]) - 40, int(c[1]) - 40
        out = tmp_path / f"nc{level:g}.png"
        assert main(["render", str(path), "--trial", str(int(row["trial"])), "--interval", "1",
                     "--gaze-deg", "16,0", "--fixation-m", "0.5", "--crop", f"{x0},{y0},80,80", "--out", str(out)]) == 0
        meta = json.loads(Path(str(out) + ".json").read_text())
        assert meta["mode"] == mode
        image = mpimg.imread(out)[..., :3].astype(np.float64)
        sliver = image[..., 0] - image[..., 1]  # red minus green: the back disc's visible part
        measured = float(np.sum(sliver))
        exact = visible_back_area_px(crop_camera(exact_camera, x0, y0, 80, 80), back, front)
        if level == 0.0:  # conventional: the front disc hides the back one exactly
            assert exact < 1.0 and measured < 2.0
        else:
            assert measured == pytest.approx(exact, rel=0.05), level
            ys, xs = np.nonzero(sliver > 0.5)
            sides[level] = float(np.sign(xs.mean() + x0 - c[0]))
        areas[level] = measured
        # the session's camera (the plan's rig and the trial row) is the documented one
        from psyop.session.plan import compile_plan

        session_camera = compile_plan(protocol).rig.camera(display, "right", fixation, mode, row=row.to_dict())
        np.testing.assert_allclose(session_camera.centre_of_projection_m, exact_camera.centre_of_projection_m, atol=1e-15)
    assert areas[12.0] > 1.5 * areas[6.0] > 0  # more NC, more parallax
    assert sides[-6.0] == -sides[6.0] and sides[6.0] == sides[12.0]  # the reversed NC shows the other side


def test_a_signed_nc_needs_a_with_against_response_and_levels_in_range() -> None:
    with pytest.raises(UserError, match="gives a rendered NC of 40 mm"):
        parse_protocol(TEXT.replace("[-6, 0, 6, 12]", "[-40, 0, 6]"), "p.yaml")
    with pytest.raises(UserError, match="set display.rendering_nc: {mm: {factor: nc_mm}, signed: true}"):
        parse_protocol(TEXT.replace(", signed: true", ""), "p.yaml")
    with pytest.raises(UserError, match="nc_nulling observer cannot answer a two_interval|only a with_against"):
        parse_protocol(TEXT.replace("response: {kind: with_against, nc_factor: nc_mm}",
                                    "response: {kind: two_interval, test: {mode: ocular}, reference: {mode: conventional},"
                                    " level_factor: nc_mm}"), "p.yaml")
    with pytest.raises(UserError, match="'nc_m' is not a factor"):
        parse_protocol(TEXT.replace("nc_factor: nc_mm", "nc_factor: nc_m"), "p.yaml")


def test_the_shipped_example_validates_and_its_observer_answers_from_the_rendered_nc() -> None:
    """The simulated observer's p(against) is 0.5 at its own NC, read from the trial's mode and the rig's NC rule
    (a row whose schedule column lies about the NC does not change its answer)."""
    from psyop.session.plan import compile_plan
    from psyop.session.responses.simulated import make_observer

    protocol = load_protocol(EXAMPLE)
    plan = compile_plan(protocol)
    observer = make_observer(plan.observer_params(), seed=3, participant="S01")
    own = observer.participant_state["own_nc_mm"]
    assert own != pytest.approx(7.6916)  # between-subject sd: each participant's NC is its own
    row = {"trial": 0, "trial_seed": 1, "mode_interval1": "ocular", "nc_mm": own, "rendered_nc_mm": -99.0}
    assert observer.model.probability(row, observer.participant_state) == pytest.approx(0.5)
    from scipy.stats import norm

    for level, mode in ((-4.0, "reversed"), (0.0, "conventional"), (own + 6.0, "ocular")):
        expected = 0.02 + 0.96 * norm.cdf((level - own) / 4.0)  # the example's lapse and width
        assert observer.model.probability({**row, "nc_mm": abs(level) if level else 0.0, "mode_interval1": mode},
                                         observer.participant_state) == pytest.approx(expected, abs=1e-12), level
