"""assets/: the committed glTF files are what assets/build_assets.py writes (byte for byte), and
they are the scenes assets/README.md describes."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from psyop.mesh import AlphaMode, load_mesh

ASSETS = Path(__file__).resolve().parents[2] / "assets"


def _builder():  # type: ignore[no-untyped-def]
    spec = importlib.util.spec_from_file_location("build_assets", ASSETS / "build_assets.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_build_script_regenerates_the_committed_files_byte_for_byte(tmp_path: Path) -> None:
    written = _builder().build(tmp_path)
    assert sorted(p.name for p in written) == ["dining_room.glb", "pencil.glb", "teaser.glb"]
    for path in written:
        assert path.read_bytes() == (ASSETS / path.name).read_bytes(), (
            f"assets/{path.name} differs from what assets/build_assets.py writes; run `python assets/build_assets.py`")
        assert path.stat().st_size < 1 << 20


def test_dining_room() -> None:
    room = load_mesh(Path("dining_room.glb"), base_dir=ASSETS)
    assert 5_000 <= room.triangle_count <= 20_000
    np.testing.assert_allclose(room.bbox_min, [-2.0, 0.0, -4.5], atol=1e-6)
    np.testing.assert_allclose(room.bbox_max, [2.0, 2.62, 0.5], atol=1e-6)
    nodes = {p.node for p in room.parts}
    for name in ("floor", "back_wall", "front_wall", "left_wall", "right_wall", "table_top", "chair0_seat",
                 "chair1_seat", "plate0", "plate1", "plate2", "candle_wax", "bottle_glass", "bottle_label"):
        assert name in nodes, name
    textured = {p.node for p in room.parts if p.texture is not None}
    assert {"floor", "back_wall", "front_wall", "left_wall", "right_wall", "bottle_label"} <= textured
    inside = np.array([0.0, 1.3, -2.0])
    for part in room.parts:
        if part.node in ("floor", "back_wall", "front_wall", "left_wall", "right_wall"):
            tris = part.positions[part.indices]
            face = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
            assert np.all(np.einsum("ij,ij->i", face, inside - tris.mean(axis=1)) > 0), f"{part.node} faces out"
    blend = [p.node for p in room.parts if p.alpha_mode is AlphaMode.BLEND]
    assert sorted(blend) == ["candle_flame", "wine_glass0", "wine_glass1"]
    assert [p.node for p in room.parts[-3:]] == blend  # drawn last


def test_pencil_is_19_cm_along_x_and_centred() -> None:
    pencil = load_mesh(Path("pencil.glb"), "pencil", base_dir=ASSETS)
    extent = pencil.bbox_max - pencil.bbox_min
    assert extent[0] == pytest.approx(0.19, abs=1e-6) and pencil.largest_extent == pytest.approx(0.19, abs=1e-6)
    np.testing.assert_allclose((pencil.bbox_max + pencil.bbox_min) / 2, 0.0, atol=1e-6)
    assert extent[1] < 0.01 and extent[2] < 0.01


def test_teaser_candle_stands_in_front_of_the_bottle() -> None:
    candle = load_mesh(Path("teaser.glb"), "candle", base_dir=ASSETS)
    bottle = load_mesh(Path("teaser.glb"), "bottle", base_dir=ASSETS)
    assert candle.bbox_min[2] > bottle.bbox_max[2]  # wholly nearer the viewer (who looks along -z)
    # seen along -z the candle covers the bottle's middle but not its edges: parallax can reveal them
    assert bottle.bbox_min[0] < candle.bbox_min[0] and candle.bbox_max[0] < bottle.bbox_max[0]
    assert any(p.texture is not None for p in bottle.parts)  # the label behind the candle


@pytest.mark.parametrize("name", ["dining_room.glb", "pencil.glb", "teaser.glb"])
def test_assets_load_as_trimesh_reads_them(name: str) -> None:
    import trimesh

    ours = load_mesh(Path(name), base_dir=ASSETS)
    theirs = trimesh.load(ASSETS / name, force="scene", process=False)
    assert ours.triangle_count == sum(len(g.faces) for g in theirs.geometry.values())
    for part in ours.parts:
        world, geometry = theirs.graph[part.node]
        np.testing.assert_allclose(part.positions, trimesh.transform_points(theirs.geometry[geometry].vertices, world),
                                   atol=1e-6)
