"""Protocol scene -> rendering scene, and the ``psyop render`` command."""

from __future__ import annotations

import json
import math
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest

from psyop.cli import main
from psyop.optics.angles import polar_direction
from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.stimulus import build_scene, interval_mode

REPO = Path(__file__).resolve().parents[2]
PROTOCOLS = REPO / "protocols"
CENTRE = np.array([0.032, 0.0, 0.0])


def _angle_deg(p, q) -> float:
    p, q = np.asarray(p) / np.linalg.norm(p), np.asarray(q) / np.linalg.norm(q)
    return math.degrees(math.atan2(np.linalg.norm(np.cross(p, q)), p @ q))


def test_detection_scene_follows_the_trial_row():
    protocol = load_protocol(PROTOCOLS / "detection.yaml")
    row = compile_schedule(protocol, 5).iloc[7].to_dict()
    scene = build_scene(protocol, row, 0.25, CENTRE, interval=1)
    by_name = {p.name: p for p in scene.primitives}
    back, front = by_name["back"], by_name["front"]
    assert -back.centre_m[2] == pytest.approx(1.0 / row["back_D"])
    assert -front.centre_m[2] == pytest.approx(1.0 / (row["back_D"] + row["level_D"]))
    for disc in (back, front):  # 2 deg seen from the eye's centre of rotation
        rel = np.array(disc.centre_m) - CENTRE
        assert 2 * math.degrees(math.atan(disc.half_u_m[0] / np.linalg.norm(rel))) == pytest.approx(2.0)
    # the fixation target circles at a constant 16 deg, 90 deg/s of polar angle, from the row's start and direction
    target = np.array(by_name["fixation_outer"].centre_m) - CENTRE
    phi_deg = row["fixation_start_deg"] + row["fixation_direction"] * 90.0 * 0.25
    expected = polar_direction(16.0, phi_deg)
    assert _angle_deg(target, expected) < 1e-9
    assert _angle_deg(target, [0.0, 0.0, -1.0]) == pytest.approx(16.0, abs=1e-9)
    assert interval_mode(protocol, row, 1) in ("conventional", "ocular")
    assert {interval_mode(protocol, row, 1), interval_mode(protocol, row, 2)} == {"conventional", "ocular"}


def test_ordinal_scene_puts_the_near_surface_on_the_scheduled_side():
    protocol = load_protocol(PROTOCOLS / "ordinal.yaml")
    schedule = compile_schedule(protocol, 2)
    for side in ("left", "right"):
        row = schedule[schedule["near_side"] == side].iloc[0].to_dict()
        scene = build_scene(protocol, row, 0.0, CENTRE)
        near = next(p for p in scene.primitives if p.border is not None)
        far = next(p for p in scene.primitives if p.border is None)
        assert near.border.side == (-1 if side == "left" else 1)
        assert -near.centre_m[2] == pytest.approx(1.0 / (0.5 + row["separation_D"]))
        assert -far.centre_m[2] == pytest.approx(2.0)
        assert scene.aperture is not None and scene.aperture.radius_deg == pytest.approx(10.0)


@pytest.mark.parametrize("name", ["realism", "egocentric", "discrimination"])
def test_every_study_scene_builds(name):
    protocol = load_protocol(PROTOCOLS / f"{name}.yaml")
    row = compile_schedule(protocol, 0).iloc[0].to_dict()
    scene = build_scene(protocol, row, 0.5, CENTRE, base_dir=PROTOCOLS)
    assert len(scene.primitives) + len(scene.meshes) >= 2  # egocentric: a mesh room and a mesh pencil
    near, far = scene.depth_range_m(CENTRE)
    # discrimination's back disc and fixation target are at 0 D: optical infinity; egocentric's mesh room
    # surrounds the eye (its bounding sphere holds it: near 0), and with its pencil a mesh too the scene has no
    # primitive, whose range would bound far: far is inf (Scene._depth_range_with_meshes_m, a wider bound)
    assert 0.0 < near < far < math.inf or (name == "discrimination" and far == math.inf) or \
        (name == "egocentric" and 0.0 == near < far)


def test_render_command_writes_png_and_sidecar(tmp_path):
    out = tmp_path / "frame.png"
    rc = main(["render", str(PROTOCOLS / "detection.yaml"), "--trial", "2", "--interval", "1", "--gaze-deg",
               "16,0", "--mode", "ocular", "--crop", "688,768,64,64", "--out", str(out)])
    assert rc == 0
    img = mpimg.imread(out)
    assert img.shape[:2] == (64, 64)
    assert np.allclose(img * 255, np.round(img * 255), atol=1e-3)  # 8-bit values
    side = json.loads(Path(str(out) + ".json").read_text())
    cop = np.array(side["centre_of_projection_m"])
    centre = np.array(side["eye_centre_m"])
    assert np.linalg.norm(cop - centre) == pytest.approx(side["eye_model"]["nc_m"], rel=1e-9)
    assert side["mode"] == "ocular" and side["eye"] == "right" and side["resolution_px"] == [64, 64]
    tan = side["frustum_tangents"]
    assert tan["left"] < 0 < tan["right"] and tan["bottom"] < 0 < tan["top"]
    # the stimulus discs sit at the centre of the display: the noise disc fills the middle of the crop
    assert img[32, 32, :3].std() < 0.05  # grey noise: R = G = B, no red in the centre


def test_render_command_rejects_bad_input(tmp_path, capsys):
    rc = main(["render", str(PROTOCOLS / "detection.yaml"), "--trial", "100000", "--out", str(tmp_path / "x.png")])
    assert rc == 2
    assert "--trial" in capsys.readouterr().err
    rc = main(["render", str(PROTOCOLS / "detection.yaml"), "--gaze-deg", "nan,0", "--out", str(tmp_path / "x.png")])
    assert rc == 2


def test_render_gaze_takes_a_negative_azimuth_the_polar_form_and_the_sessions_ipd(tmp_path):
    """``--gaze-deg -12,0`` used to fail ("expected one argument"); the default ipd was 64 mm where sessions use 63."""
    from psyop.optics.angles import fick_direction
    from psyop.optics.ranges import DEFAULT_IPD_M  # the one default (render and sessions alike)

    sides = []
    for option, value in (("--gaze-deg", "-12,0"), ("--gaze-polar-deg", "12,180")):
        out = tmp_path / f"{option.strip('-')}.png"
        rc = main(["render", str(PROTOCOLS / "detection.yaml"), option, value, "--mode", "ocular",
                   "--crop", "0,0,8,8", "--out", str(out)])
        assert rc == 0
        sides.append(json.loads(Path(str(out) + ".json").read_text()))
    assert sides[0]["gaze_deg"] == [-12.0, 0.0]
    assert sides[1]["gaze_deg"] == pytest.approx([-12.0, 0.0], abs=1e-12)
    assert sides[0]["ipd_m"] == pytest.approx(DEFAULT_IPD_M) == pytest.approx(0.063)
    fixation = np.array(sides[0]["fixation_m"]) - np.array(sides[0]["eye_centre_m"])
    assert _angle_deg(fixation, fick_direction(-12.0, 0.0)) < 1e-9


def test_render_refuses_a_gaze_beyond_89_deg(tmp_path, capsys):
    rc = main(["render", str(PROTOCOLS / "detection.yaml"), "--gaze-deg", "-89.5,0", "--out", str(tmp_path / "x.png")])
    assert rc == 2
    assert "within +-89 deg" in capsys.readouterr().err
