"""session.json records every model a protocol's mesh items name: file name, SHA-256, triangle count and
bounding box (MeshAsset.record), read from the file as the session opens (a protocol written here)."""

from __future__ import annotations

import hashlib
import json
import shutil
import sys
from pathlib import Path

from psyop.cli import main as cli_main
from psyop.mesh import load_mesh

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from protocol_texts import TWO_INTERVAL_TAIL

ASSETS = Path(__file__).resolve().parents[2] / "assets"

PROTOCOL = """psyop_protocol: 1
study: {name: mesh_record, title: two teaser nodes and a pencil}
display: {profile: vive_pro, eye_model: gullstrand_emsley_relaxed, ipd: {mm: 64}}
eyes: right
scene:
  - {id: candle, kind: mesh, file: models/teaser.glb, node: candle, depth: {m: 0.5}}
  - {id: bottle, kind: mesh, file: models/teaser.glb, node: bottle, depth: {m: 0.75}}
  - {id: pencil, kind: mesh, file: models/pencil.glb, depth: {m: 0.6}, size_m: 0.19}
""" + TWO_INTERVAL_TAIL.replace("duration_s: 1}", "duration_s: 0.05}") + """observer:
  kind: psychometric_2afc
  level_column: level_D
  threshold_D: 0.36
  width_D: 0.2
"""


def test_session_json_records_each_model_and_node(tmp_path):
    (tmp_path / "models").mkdir()
    for name in ("teaser.glb", "pencil.glb"):
        shutil.copy(ASSETS / name, tmp_path / "models" / name)
    protocol = tmp_path / "mesh_record.yaml"
    protocol.write_text(PROTOCOL)
    data = tmp_path / "data"
    assert cli_main(["run", str(protocol), "--participant", "P1", "--data", str(data), "--render", "cameras"]) == 0
    (session,) = data.glob("mesh_record/sub-P1/ses-*/session.json")
    recorded = json.loads(session.read_text())["meshes"]
    assert [(r["file"], r["node"]) for r in recorded] == [("teaser.glb", "candle"), ("teaser.glb", "bottle"),
                                                           ("pencil.glb", None)]
    for record in recorded:
        path = tmp_path / "models" / str(record["file"])
        assert record["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()  # of the file, independently
        asset = load_mesh(path, record["node"], base_dir=path.parent)
        assert record["triangle_count"] == asset.triangle_count > 0
        assert record["bbox_min"] == [float(v) for v in asset.bbox_min]
        assert record["bbox_max"] == [float(v) for v in asset.bbox_max]
    assert recorded[0]["triangle_count"] + recorded[1]["triangle_count"] == load_mesh(
        tmp_path / "models" / "teaser.glb", None, base_dir=tmp_path / "models").triangle_count


def test_a_protocol_without_meshes_records_an_empty_list(tmp_path):
    text = PROTOCOL.split("scene:\n")[0] + "scene:\n  - {id: disc, kind: disc, size_deg: 2, depth: {D: 1}, surface: {kind: solid, rgb: [1, 1, 1]}}\n" \
        + PROTOCOL.split("size_m: 0.19}\n")[1]
    protocol = tmp_path / "flat.yaml"
    protocol.write_text(text.replace("mesh_record", "flat_record"))
    data = tmp_path / "data"
    assert cli_main(["run", str(protocol), "--participant", "P1", "--data", str(data), "--render", "cameras"]) == 0
    (session,) = data.glob("flat_record/sub-P1/ses-*/session.json")
    assert json.loads(session.read_text())["meshes"] == []
