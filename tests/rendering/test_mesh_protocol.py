"""``kind: mesh`` scene items: validated (the model read through psyop.mesh.load, one line at the item),
placed and drawn (a protocol written here, not one of protocols/)."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from psyop.errors import UserError
from psyop.protocol.loader import parse_protocol
from psyop.rendering import Renderer, RenderSettings
from psyop.rendering.camera_math import project_points_px
from psyop.rendering.measure import RIGHT_CENTRE_M, right_eye_camera
from psyop.stimulus import build_scene

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from protocol_texts import TWO_INTERVAL_TAIL

ASSETS = Path(__file__).resolve().parents[2] / "assets"

HEAD = """psyop_protocol: 1
study: {name: mesh_item, title: a mesh pencil in front of a grey wall}
display: {profile: vive_pro, eye_model: gullstrand_emsley_relaxed, ipd: {mm: 64}}
eyes: right
scene:
  - id: pencil
    kind: mesh
    file: %s
    depth: {m: 0.6}
    centre_deg: [2, -1]
    size_deg: 10
    rotation_deg: [0, 0, 30]
  - id: wall
    kind: quad
    width_deg: 40
    height_deg: 40
    depth: {D: 0.5}
    surface: {kind: solid, rgb: [0.3, 0.3, 0.3]}
"""


def _protocol(tmp_path: Path, file: str = "pencil.glb"):
    shutil.copy(ASSETS / "pencil.glb", tmp_path / "pencil.glb")
    return parse_protocol(HEAD % file + TWO_INTERVAL_TAIL, str(tmp_path / "p.yaml"), base_dir=tmp_path)


def test_a_mesh_item_validates_builds_and_draws_in_front_of_the_wall(tmp_path, gl_context):
    protocol = _protocol(tmp_path)
    scene = build_scene(protocol, {"level_D": 0.0, "trial_seed": 1}, 0.0, RIGHT_CENTRE_M, base_dir=tmp_path)
    assert len(scene.meshes) == 1 and scene.meshes[0].name == "pencil"
    inst = scene.meshes[0]
    centre, _ = inst.bounding_sphere_m()
    assert np.linalg.norm(centre - RIGHT_CENTRE_M) == pytest.approx(0.6)
    cam = right_eye_camera(2.0, -1.0, "ocular")
    with Renderer(scene, RenderSettings(reuse_tolerance_px=None), ctx=gl_context) as renderer:
        renderer.render(cam)
        img = renderer.image()
    wall = np.all(np.abs(img - 0.3) < 1e-3, axis=-1)
    x, y = project_points_px(cam, [centre])[0]
    window = ~wall[int(y) - 60:int(y) + 60, int(x) - 60:int(x) + 60]
    assert window.sum() > 50  # the pencil covers the wall around its centre


def test_a_bad_model_fails_validation_at_the_item(tmp_path):
    (tmp_path / "broken.glb").write_text("not a model")
    with pytest.raises(UserError) as error:
        _protocol(tmp_path, "broken.glb")
    assert "broken.glb" in str(error.value)


def test_placement_fields_are_exclusive(tmp_path):
    text = (HEAD % "pencil.glb").replace("    size_deg: 10\n", "    size_deg: 10\n    scale: 2\n")
    shutil.copy(ASSETS / "pencil.glb", tmp_path / "pencil.glb")
    with pytest.raises(UserError) as error:
        parse_protocol(text + TWO_INTERVAL_TAIL, str(tmp_path / "p.yaml"), base_dir=tmp_path)
    assert "at most one of scale" in str(error.value)
