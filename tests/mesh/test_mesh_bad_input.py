"""Every bad model psyop refuses: one line naming the file (and node/mesh/primitive) and the fix."""

from __future__ import annotations

import base64
import json
import struct
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from raw_gltf import RawGltf, quad

from psyop.errors import UserError
from psyop.mesh import load_mesh
from psyop.mesh import load as load_module


def _model(**mesh_kw: object) -> RawGltf:
    raw = RawGltf()
    positions, indices, uv = quad()
    raw.node(name="square", mesh=raw.mesh(positions, indices, TEXCOORD_0=uv, **mesh_kw))  # type: ignore[arg-type]
    raw.node(name="lamp")
    return raw


def _refused(tmp_path: Path, name: str, *needles: str, node: str | None = None) -> str:
    with pytest.raises(UserError) as caught:
        load_mesh(Path(name), node, base_dir=tmp_path)
    message = str(caught.value)
    assert "\n" not in message and name in message, message
    for needle in needles:
        assert needle in message, message
    return message


def _glb(tmp_path: Path, edit: Callable[[bytes], bytes] | None = None) -> None:
    path = _model().save_glb(tmp_path / "m.glb")
    if edit is not None:
        path.write_bytes(edit(path.read_bytes()))


def test_truncated_glb(tmp_path: Path) -> None:
    _glb(tmp_path, lambda b: b[: len(b) - 10])
    _refused(tmp_path, "m.glb", "truncated", "re-export")
    _glb(tmp_path, lambda b: b[:7])
    _refused(tmp_path, "m.glb", "truncated")


def test_wrong_magic_and_version(tmp_path: Path) -> None:
    _glb(tmp_path, lambda b: b"glTX" + b[4:])
    _refused(tmp_path, "m.glb", "magic")
    _glb(tmp_path, lambda b: b[:4] + struct.pack("<I", 1) + b[8:])
    _refused(tmp_path, "m.glb", "version 1")


def test_corrupt_json_chunk_and_bad_gltf_version(tmp_path: Path) -> None:
    _glb(tmp_path, lambda b: b[:20] + b"\xff\xfe" + b[22:])
    _refused(tmp_path, "m.glb", "JSON")
    raw = _model()
    raw.doc["asset"]["version"] = "1.0"
    raw.save_gltf(tmp_path / "old.gltf")
    _refused(tmp_path, "old.gltf", "glTF version '1.0'", "2.0")
    (tmp_path / "text.gltf").write_text("not json")
    _refused(tmp_path, "text.gltf", "not glTF 2.0 JSON")


def test_missing_bin_and_texture(tmp_path: Path) -> None:
    _model().save_gltf(tmp_path / "m.gltf", bin_name="gone.bin")
    (tmp_path / "gone.bin").unlink()
    _refused(tmp_path, "m.gltf", "buffer 0", "gone.bin", "not found")
    raw = _model(material=None)
    raw.doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
    raw.doc["meshes"][0]["primitives"][0]["material"] = 0
    raw.doc["images"], raw.doc["textures"] = [{"uri": "missing.png"}], [{"source": 0}]
    raw.save_gltf(tmp_path / "t.gltf", bin_name="t.bin")
    _refused(tmp_path, "t.gltf", "image 0", "missing.png", "not found")


@pytest.mark.parametrize("uri", ["../outside.bin", "sub/../../outside.bin", "/etc/passwd", "file:///etc/passwd",
                                 "http://example.com/m.bin", "https://example.com/m.bin", "C:\\models\\m.bin",
                                 "..\\outside.bin", "%2e%2e/outside.bin", "%2Fetc%2Fpasswd"])
def test_uris_that_leave_the_models_folder(tmp_path: Path, uri: str) -> None:
    folder = tmp_path / "model"
    folder.mkdir()
    _model().save_gltf(folder / "m.gltf", bin_name="m.bin")
    (tmp_path / "outside.bin").write_bytes((folder / "m.bin").read_bytes())
    doc = json.loads((folder / "m.gltf").read_text())
    doc["buffers"][0]["uri"] = uri
    (folder / "m.gltf").write_text(json.dumps(doc))
    _refused(folder, "m.gltf", "buffer 0", "model's folder")


def test_symlink_out_of_the_folder(tmp_path: Path) -> None:
    folder = tmp_path / "model"
    folder.mkdir()
    _model().save_gltf(folder / "m.gltf", bin_name="real.bin")
    (tmp_path / "real.bin").write_bytes((folder / "real.bin").read_bytes())
    (folder / "real.bin").unlink()
    (folder / "real.bin").symlink_to(tmp_path / "real.bin")
    _refused(folder, "m.gltf", "outside the model's folder")


def test_oversized_and_malformed_data_uris(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    raw = _model()
    doc = raw.document()
    doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(bytes(raw.blob)).decode()
    (tmp_path / "d.gltf").write_text(json.dumps(doc))
    monkeypatch.setattr(load_module, "MAX_DATA_URI_BYTES", 100)
    _refused(tmp_path, "d.gltf", "data: URI", "over the 100 byte limit", ".glb")
    monkeypatch.undo()
    doc["buffers"][0]["uri"] = "data:application/octet-stream;base64,@@@@"
    (tmp_path / "d.gltf").write_text(json.dumps(doc))
    _refused(tmp_path, "d.gltf", "not valid base64")


def test_file_over_the_size_limit(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _glb(tmp_path)
    monkeypatch.setattr(load_module, "MAX_MESH_FILE_BYTES", 64)
    _refused(tmp_path, "m.glb", "over the 64 byte limit")


def test_too_many_triangles(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _glb(tmp_path)
    monkeypatch.setattr(load_module, "MAX_MESH_TRIANGLES", 1)
    _refused(tmp_path, "m.glb", "2 triangles", "decimate")


@pytest.mark.parametrize("mode, name", [(0, "POINTS"), (1, "LINES"), (2, "LINE_LOOP"), (3, "LINE_STRIP")])
def test_points_and_lines(tmp_path: Path, mode: int, name: str) -> None:
    _model(mode=mode).save_glb(tmp_path / "m.glb")
    _refused(tmp_path, "m.glb", name, "node 0 ('square'), mesh 0 primitive 0", "triangles only")


@pytest.mark.parametrize("extension", ["KHR_draco_mesh_compression", "EXT_meshopt_compression", "KHR_texture_basisu"])
def test_required_extensions_psyop_does_not_read(tmp_path: Path, extension: str) -> None:
    raw = _model()
    raw.doc["extensionsUsed"] = raw.doc["extensionsRequired"] = [extension]
    raw.save_glb(tmp_path / "m.glb")
    _refused(tmp_path, "m.glb", extension, "re-export")


def test_honoured_required_extension_loads(tmp_path: Path) -> None:
    raw = _model()
    raw.doc["extensionsUsed"] = raw.doc["extensionsRequired"] = ["KHR_materials_unlit"]
    raw.save_glb(tmp_path / "m.glb")
    assert load_mesh(Path("m.glb"), base_dir=tmp_path).triangle_count == 2


@pytest.mark.parametrize("value", [np.nan, np.inf])
def test_non_finite_vertices(tmp_path: Path, value: float) -> None:
    raw = RawGltf()
    positions, indices, _ = quad()
    positions[2, 1] = value
    raw.node(name="bad", mesh=raw.mesh(positions, indices))
    raw.save_glb(tmp_path / "m.glb")
    _refused(tmp_path, "m.glb", "vertex 2 is not finite", "node 0 ('bad'), mesh 0 primitive 0")


def test_out_of_range_indices_and_ragged_lists(tmp_path: Path) -> None:
    raw = RawGltf()
    positions, _, _ = quad()
    raw.node(name="bad", mesh=raw.mesh(positions, np.array([0, 1, 7], dtype=np.uint16)))
    raw.save_glb(tmp_path / "m.glb")
    _refused(tmp_path, "m.glb", "index 7 is out of range for its 4 vertices")
    raw = RawGltf()
    raw.node(name="ragged", mesh=raw.mesh(positions, np.array([0, 1, 2, 3], dtype=np.uint16)))
    raw.save_glb(tmp_path / "r.glb")
    _refused(tmp_path, "r.glb", "4 indices do not make whole triangles")


def test_accessor_past_its_buffer_view(tmp_path: Path) -> None:
    raw = _model()
    raw.doc["accessors"][0]["count"] = 400
    raw.save_glb(tmp_path / "m.glb")
    _refused(tmp_path, "m.glb", "accessor 0", "do not fit")


def test_unknown_and_ambiguous_node(tmp_path: Path) -> None:
    _glb(tmp_path)
    _refused(tmp_path, "m.glb", "no node named 'lamp_shade'", "'square', 'lamp'", node="lamp_shade")
    _refused(tmp_path, "m.glb", "node 'lamp' has no triangles", node="lamp")
    raw = _model()
    raw.node(name="square", mesh=0)
    raw.save_glb(tmp_path / "twice.glb")
    _refused(tmp_path, "twice.glb", "2 nodes are named 'square'", node="square")


def test_node_cycle(tmp_path: Path) -> None:
    raw = _model()
    raw.doc["nodes"][0]["children"] = [1]
    raw.doc["nodes"][1]["children"] = [0]
    raw.save_glb(tmp_path / "m.glb")
    _refused(tmp_path, "m.glb", "appears twice")


def test_skins_morph_targets_and_texcoord_1(tmp_path: Path) -> None:
    raw = _model()
    raw.doc["nodes"][0]["skin"] = 0
    raw.save_glb(tmp_path / "s.glb")
    _refused(tmp_path, "s.glb", "skinned")
    raw = _model()
    raw.doc["meshes"][0]["primitives"][0]["targets"] = [{"POSITION": 0}]
    raw.doc["meshes"][0]["weights"] = [0.5]
    raw.save_glb(tmp_path / "t.glb")
    _refused(tmp_path, "t.glb", "morph targets")
    raw = _model()
    raw.doc["images"], raw.doc["textures"] = [{"uri": "x.png"}], [{"source": 0}]
    raw.doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0, "texCoord": 1}}}]
    raw.doc["meshes"][0]["primitives"][0]["material"] = 0
    raw.save_glb(tmp_path / "u.glb")
    _refused(tmp_path, "u.glb", "TEXCOORD_1", "material 0")


def test_undecodable_texture(tmp_path: Path) -> None:
    raw = _model()
    raw.doc["images"], raw.doc["textures"] = [{"uri": "checker.png"}], [{"source": 0}]
    raw.doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
    raw.doc["meshes"][0]["primitives"][0]["material"] = 0
    raw.save_gltf(tmp_path / "m.gltf")
    (tmp_path / "checker.png").write_text("this is not a PNG\n")
    _refused(tmp_path, "m.gltf", "image 0 (checker.png)", "not a readable PNG or JPEG")


def test_wrong_types_are_refused_not_tracebacks(tmp_path: Path) -> None:
    raw = _model()
    raw.doc["nodes"][0]["translation"] = ["a", 0, 0]
    raw.save_gltf(tmp_path / "a.gltf")  # pygltflib's writer itself refuses this document
    _refused(tmp_path, "a.gltf", "not a valid glTF 2.0 document")
    raw = _model()
    raw.doc["nodes"][0]["mesh"] = 9
    raw.save_glb(tmp_path / "b.glb")
    _refused(tmp_path, "b.glb", "mesh 9 does not exist")
    (tmp_path / "c.gltf").write_text(json.dumps({"asset": {"version": "2.0"}, "nodes": "zzz"}))
    with pytest.raises(UserError):
        load_mesh(Path("c.gltf"), base_dir=tmp_path)


def test_not_a_model_file(tmp_path: Path) -> None:
    (tmp_path / "m.obj").write_text("v 0 0 0\n")
    _refused(tmp_path, "m.obj", ".gltf or .glb")
    _refused(tmp_path, "absent.glb", "not found")


def test_zero_scale_node_is_hidden_not_an_error(tmp_path: Path) -> None:
    raw = _model()
    raw.node(name="hidden", mesh=0, scale=[0.0, 0.0, 0.0])
    raw.save_glb(tmp_path / "m.glb")
    assert [p.node for p in load_mesh(Path("m.glb"), base_dir=tmp_path).parts] == ["square"]
    _refused(tmp_path, "m.glb", "node 'hidden' has no triangles", node="hidden")


@pytest.mark.parametrize("fmt, ok", [("JPEG", True), ("PNG", True), ("GIF", False), ("BMP", False)])
def test_texture_formats(tmp_path: Path, fmt: str, ok: bool) -> None:
    import io

    from PIL import Image

    out = io.BytesIO()
    Image.fromarray(np.full((4, 4, 3), 128, dtype=np.uint8)).save(out, format=fmt)
    raw = _model()
    raw.doc["images"] = [{"uri": "data:image/x;base64," + base64.b64encode(out.getvalue()).decode()}]
    raw.doc["textures"] = [{"source": 0}]
    raw.doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
    raw.doc["meshes"][0]["primitives"][0]["material"] = 0
    raw.save_glb(tmp_path / "m.glb")
    if ok:
        tex = load_mesh(Path("m.glb"), base_dir=tmp_path).parts[0].texture
        assert tex is not None and tex.rgba_linear.shape == (4, 4, 4)
        np.testing.assert_allclose(tex.rgba_linear[..., 3], 1.0)
    else:
        _refused(tmp_path, "m.glb", f"a {fmt} image", "PNG or JPEG")
