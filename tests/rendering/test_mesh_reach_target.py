"""A ``reach_target`` whose ``object`` is a glTF model (issue 26): ``object: {file, node, rotation_deg}``.

Its semantics are the analytic target's, read off the model's bounding box: the box's centre is where the
target is (straight ahead, at ``distance_fraction`` of the arm reach, ``height_m``: the point the reach is
measured towards, psyop/session/reach.py) and its largest side is ``size_m``. Checked on the placed vertices,
in a rendered frame against exact ray-triangle coverage, at validation (a bad node at the object's line), and
in a headless run of protocols/egocentric.yaml with its pencil made a mesh."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from psyop.cli import main as cli_main
from psyop.errors import UserError
from psyop.optics.camera import make_eye_camera
from psyop.optics.display import VIVE_PRO
from psyop.protocol.loader import parse_protocol
from psyop.rendering import Renderer, RenderSettings
from psyop.rendering.camera_math import crop_camera, project_points_px
from psyop.rendering.measure import FIXTURE_IPD_M as IPD_M, NC_M, RIGHT_CENTRE_M
from psyop.rendering.mesh_exact import exact_coverage
from psyop.stimulus import build_scene
from tests.protocol_texts import EGOCENTRIC_MESH_PENCIL as PENCIL

PROTOCOLS = Path(__file__).resolve().parents[2] / "protocols"
EGOCENTRIC = PROTOCOLS / "egocentric.yaml"


def _text(obj: str = "{file: ../assets/pencil.glb, node: pencil, rotation_deg: [90, 0, 0]}",
          room: bool = True) -> str:
    text = EGOCENTRIC.read_text()
    assert PENCIL in text
    text = text.replace(PENCIL, f"    object: {obj}\n")
    if not room:
        text = text.replace("    file: ../assets/dining_room.glb\n", "    file: ../assets/teaser.glb\n    node: candle\n")
    return text


def _protocol(text: str, where: Path = EGOCENTRIC):
    return parse_protocol(text, str(where), base_dir=where.parent)


def _pencil(protocol, fraction: float = 0.5):
    row = {"rendering": "enabled", "target_fraction": fraction, "trial_seed": 1}
    scene = build_scene(protocol, row, 0.0, RIGHT_CENTRE_M, base_dir=EGOCENTRIC.parent, arm_reach_m=0.7,
                        show=["pencil"])
    (instance,) = scene.meshes
    return scene, instance


def _placed(instance) -> np.ndarray:
    m = np.asarray(instance.model_m).reshape(4, 4)
    points = np.concatenate([p.positions for p in instance.asset.parts])
    return points @ m[:3, :3].T + m[:3, 3]


@pytest.mark.parametrize("rotation", ["[0, 0, 0]", "[90, 0, 0]", "[30, 20, 10]"])
def test_the_models_bounding_box_centre_is_the_target_and_its_largest_side_the_size(rotation):
    protocol = _protocol(_text(f"{{file: ../assets/pencil.glb, node: pencil, rotation_deg: {rotation}}}"))
    _, instance = _pencil(protocol, 0.5)
    assert instance.name == "pencil" and (instance.asset.path.name, instance.asset.node) == ("pencil.glb", "pencil")
    m = np.asarray(instance.model_m).reshape(4, 4)
    box_centre = (instance.asset.bbox_min + instance.asset.bbox_max) / 2
    np.testing.assert_allclose(m[:3, :3] @ box_centre + m[:3, 3], [0.0, -0.15, -0.35], atol=1e-12)
    scale = np.linalg.norm(m[:3, 0])
    assert scale * instance.asset.largest_extent == pytest.approx(0.19, rel=1e-12)
    if rotation == "[0, 0, 0]":  # unturned: the placed vertices' own box
        placed = _placed(instance)
        np.testing.assert_allclose((placed.min(0) + placed.max(0)) / 2, [0.0, -0.15, -0.35], atol=1e-12)
        assert (placed.max(0) - placed.min(0)).max() == pytest.approx(0.19, rel=1e-12)


def test_the_drawn_target_equals_exact_coverage(gl_context):
    _, instance = _pencil(_protocol(_text()), 0.67)
    scene = build_scene(_protocol(_text()), {"rendering": "enabled", "target_fraction": 0.67, "trial_seed": 1}, 0.0,
                        RIGHT_CENTRE_M, base_dir=EGOCENTRIC.parent, arm_reach_m=0.7, show=["pencil"])
    target = np.array([0.0, -0.15, -0.67 * 0.7])
    full = make_eye_camera(VIVE_PRO, "right", target, IPD_M, NC_M, "ocular", 0.01, 100.0)
    x, y = project_points_px(full, [target])[0]
    cam = crop_camera(full, int(x) - 120, int(y) - 60, 240, 120)
    with Renderer(scene, RenderSettings(reuse_tolerance_px=None), ctx=gl_context) as renderer:
        renderer.render(cam)
        img = renderer.image().astype(np.float64)
    drawn = np.abs(img[..., :3] - np.asarray(scene.background)[:3]).max(axis=-1) > 1e-3
    exact = exact_coverage(cam, scene, samples_per_axis=4)["pencil"] > 0
    assert exact.sum() > 300
    assert (drawn != exact).sum() <= 0.03 * exact.sum() + 10, ((drawn != exact).sum(), exact.sum())


def test_a_bad_model_is_refused_at_the_objects_line():
    text = _text("{file: ../assets/pencil.glb, node: pencil_tip}")
    with pytest.raises(UserError) as error:
        _protocol(text)
    line = next(i for i, row in enumerate(text.splitlines(), 1) if "pencil_tip" in row)
    assert f"egocentric.yaml:{line}:" in str(error.value) and "no node named 'pencil_tip'" in str(error.value)
    assert "at scene[1].object.node" in str(error.value)


def test_a_mesh_reach_target_runs_headless_and_is_recorded(tmp_path):
    (tmp_path / "protocols").mkdir()
    (tmp_path / "assets").mkdir()
    for name in ("pencil.glb", "teaser.glb"):
        shutil.copy(PROTOCOLS.parent / "assets" / name, tmp_path / "assets" / name)
    path = tmp_path / "protocols" / "egocentric.yaml"
    path.write_text(_text(room=False).replace("repetitions: 5 ", "repetitions: 1 "))
    data = tmp_path / "data"
    assert cli_main(["run", str(path), "--participant", "P1", "--data", str(data), "--render", "images",
                     "--no-progress"]) == 0
    (session,) = data.glob("egocentric/sub-P1/ses-*/session.json")
    meta = json.loads(session.read_text())
    assert meta["status"] == "complete"
    assert [(m["file"], m["node"]) for m in meta["meshes"]] == [("teaser.glb", "candle"), ("pencil.glb", "pencil")]
