"""``file: {factor: NAME}`` and ``node: {factor: NAME}`` on a mesh item (issue 26): a factor of words picks the
model a trial shows. Validated (every level's file and node exist, the triangle budget per level, errors at
the item's line naming the level), each model loaded once per session although it shows in several trials,
and each trial's frame drawn with its level's model: the rendered silhouette equals exact ray-triangle coverage
(psyop.rendering.mesh_exact) of the same model placed by a protocol that names it plainly (not the schedule's
path), and differs from the other levels' models."""

from __future__ import annotations

import collections
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

import psyop.mesh.load as mesh_load
import psyop.protocol.semantics as semantics
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

ASSETS = Path(__file__).resolve().parents[2] / "assets"
MODELS = [("teaser.glb", "bottle"), ("teaser.glb", "candle"), ("pencil.glb", "pencil")]

HEAD = """psyop_protocol: 1
study: {name: mesh_factor, title: a factor picks the model}
display: {profile: vive_pro, eye_model: gullstrand_emsley_relaxed, ipd: {mm: 64}}
eyes: right
scene:
  - id: model
    kind: mesh
    file: %s
    node: %s
    depth: {m: 0.8}
    centre_deg: [0, 0]
    size_deg: 8
trial:
  phases:
    - {kind: interval, duration_s: 1}
    - {kind: interval, duration_s: 1}
    - {kind: response, expected_s: 1}
design:
  factors:
    level_D: {levels: [0, 1]}
"""
FACTORS = """    model_file: {levels: [teaser.glb, pencil.glb]}
    model_node:
      depends_on: model_file
      levels_by: {teaser.glb: [bottle, candle], pencil.glb: [%s]}
"""
TAIL = """  repetitions: 1
  randomisation: {kind: full}
response:
  kind: two_interval
  test: {mode: ocular}
  reference: {mode: conventional}
  level_factor: level_D
  order: balanced
observer: {kind: psychometric_2afc, level_column: level_D, threshold_D: 0.5, width_D: 0.2}
"""


def _write(tmp_path: Path, pencil_node: str = "pencil") -> Path:
    for name in ("teaser.glb", "pencil.glb"):
        shutil.copy(ASSETS / name, tmp_path / name)
    path = tmp_path / "p.yaml"
    path.write_text(HEAD % ("{factor: model_file}", "{factor: model_node}") + FACTORS % pencil_node + TAIL)
    return path


def _parse(path: Path):
    return parse_protocol(path.read_text(), str(path), base_dir=path.parent)


def _camera():
    full = make_eye_camera(VIVE_PRO, "right", RIGHT_CENTRE_M + np.array([0.0, 0.0, -0.8]), IPD_M, NC_M,
                           "conventional", 0.01, 100.0)
    x, y = project_points_px(full, [RIGHT_CENTRE_M + np.array([0.0, 0.0, -0.8])])[0]
    return crop_camera(full, int(x) - 80, int(y) - 80, 160, 160)


def _rendered_mask(scene, cam, ctx) -> np.ndarray:
    with Renderer(scene, RenderSettings(reuse_tolerance_px=None), ctx=ctx) as renderer:
        renderer.render(cam)
        img = renderer.image().astype(np.float64)
    background = np.asarray(scene.background, dtype=np.float64)[:3]
    return np.abs(img[..., :3] - background).max(axis=-1) > 1e-3


def test_each_trial_draws_its_levels_model(tmp_path, gl_context):
    path = _write(tmp_path)
    protocol = _parse(path)
    cam = _camera()
    exact_masks = {}
    for file, node in MODELS:  # the expected model: a protocol naming it plainly, through the exact path
        plain = tmp_path / f"plain_{node}.yaml"
        plain.write_text(HEAD % (file, node) + TAIL)
        scene = build_scene(_parse(plain), {"level_D": 0.0, "trial_seed": 1}, 0.0, RIGHT_CENTRE_M,
                            base_dir=tmp_path)
        exact_masks[(file, node)] = exact_coverage(cam, scene, samples_per_axis=4)["model"] > 0
    for file, node in MODELS:
        row = {"level_D": 0.0, "model_file": file, "model_node": node, "trial_seed": 1}
        scene = build_scene(protocol, row, 0.0, RIGHT_CENTRE_M, base_dir=tmp_path)
        (instance,) = scene.meshes
        assert (instance.asset.path.name, instance.asset.node) == (file, node)
        drawn = _rendered_mask(scene, cam, gl_context)
        expected = exact_masks[(file, node)]
        assert expected.sum() > 200
        # MSAA 4 against 16 exact samples per pixel: a pixel counts when any sample hits, in both masks
        assert (drawn != expected).sum() <= 0.03 * expected.sum() + 10, (file, node, (drawn != expected).sum())
        for other, other_mask in exact_masks.items():
            if other != (file, node):
                assert (drawn != other_mask).sum() > 5 * ((drawn != expected).sum() + 10), (file, node, other)


def test_every_level_is_validated_at_the_items_line(tmp_path):
    with pytest.raises(UserError) as error:
        _parse(_write(tmp_path, pencil_node="pencil_tip"))
    message = str(error.value)
    assert "p.yaml:9:" in message  # the item's node: line
    assert "model_node = 'pencil_tip'" in message and "no node named 'pencil_tip'" in message
    path = _write(tmp_path)
    path.write_text(path.read_text().replace("[teaser.glb, pencil.glb]", "[teaser.glb, missing.glb]")
                    .replace("pencil.glb: [pencil]", "missing.glb: [pencil]"))
    with pytest.raises(UserError) as error:
        _parse(path)
    assert "p.yaml:8:" in str(error.value) and "model_file = 'missing.glb'" in str(error.value)
    assert "not found" in str(error.value)


def test_a_numeric_factor_cannot_name_a_model(tmp_path):
    path = tmp_path / "p.yaml"
    shutil.copy(ASSETS / "pencil.glb", tmp_path / "pencil.glb")
    path.write_text(HEAD % ("pencil.glb", "{factor: level_D}") + TAIL)
    with pytest.raises(UserError) as error:
        _parse(path)
    assert "p.yaml:9:" in str(error.value) and "factor 'level_D' must have words as levels" in str(error.value)


def test_the_triangle_budget_is_checked_per_level(tmp_path, monkeypatch):
    # bottle 1920, candle 864, pencil 360 triangles: a budget of 1000 refuses the bottle's trials only
    monkeypatch.setattr(semantics, "MAX_MESH_TRIANGLES", 1000)
    with pytest.raises(UserError) as error:
        _parse(_write(tmp_path))
    message = str(error.value)
    assert "p.yaml:6:" in message and "model_node = 'bottle'" in message and "1920 mesh triangles" in message
    monkeypatch.setattr(semantics, "MAX_MESH_TRIANGLES", 1920)
    _parse(_write(tmp_path))


def test_a_session_loads_each_levels_model_once_and_records_all(tmp_path, monkeypatch):
    selections: collections.Counter = collections.Counter()
    parses: collections.Counter = collections.Counter()
    real_select, real_parse = mesh_load._select, mesh_load._parse

    def select(reader, node):
        selections[(Path(reader.path).name, node)] += 1
        return real_select(reader, node)

    def parse(path, raw):
        parses[Path(path).name] += 1
        return real_parse(path, raw)

    monkeypatch.setattr(mesh_load, "_select", select)
    monkeypatch.setattr(mesh_load, "_parse", parse)
    data = tmp_path / "data"
    assert cli_main(["run", str(_write(tmp_path)), "--participant", "P1", "--data", str(data), "--render", "images",
                     "--no-progress"]) == 0
    (session,) = data.glob("mesh_factor/sub-P1/ses-*/session.json")
    meta = json.loads(session.read_text())
    assert meta["status"] == "complete"
    assert [(m["file"], m["node"]) for m in meta["meshes"]] == MODELS
    # 6 trials (each model in 2), looked up by validation, session.json and each trial's scene: one load each,
    # and one parse per file (teaser.glb's two nodes share it)
    assert dict(selections) == {model: 1 for model in MODELS}
    assert dict(parses) == {"teaser.glb": 1, "pencil.glb": 1}
