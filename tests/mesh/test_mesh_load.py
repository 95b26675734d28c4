"""psyop.mesh.load_mesh against files another tool wrote: trimesh's glTF exporter, and documents
written field by field with pygltflib (whose transforms trimesh's own loader then checks)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image
from raw_gltf import RawGltf, quad

from psyop.mesh import AlphaMode, Filter, MeshFiles, Wrap, load_mesh
from psyop.mesh.load import srgb_to_linear


def _trimesh_scene() -> trimesh.Scene:
    """Three boxes: a root, a child under a rotated and scaled parent, and a coloured one."""
    scene = trimesh.Scene()
    tf = trimesh.transformations
    scene.add_geometry(trimesh.creation.box((0.2, 0.2, 0.2)), node_name="root_box", geom_name="root_box",
                       transform=tf.translation_matrix([0.5, 0.0, -1.0]))
    parent = tf.concatenate_matrices(tf.translation_matrix([0, 1.0, 0]), tf.rotation_matrix(0.7, [0, 1, 0]),
                                     tf.scale_matrix(2.0))
    scene.graph.update(frame_to="parent", frame_from=scene.graph.base_frame, matrix=parent)
    child = trimesh.creation.box((0.1, 0.3, 0.05))
    scene.add_geometry(child, node_name="child_box", geom_name="child_box", parent_node_name="parent",
                       transform=tf.concatenate_matrices(tf.translation_matrix([0.2, 0, 0]),
                                                         tf.rotation_matrix(-0.4, [1, 0, 0])))
    coloured = trimesh.creation.box((0.1, 0.1, 0.1))
    coloured.visual.vertex_colors = np.tile([255, 0, 0, 255], (len(coloured.vertices), 1)).astype(np.uint8)
    scene.add_geometry(coloured, node_name="red_box", geom_name="red_box",
                       transform=tf.translation_matrix([-0.5, 0, -1]))
    return scene


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_trimesh_written_scene_matches_trimeshs_world_geometry(tmp_path: Path, suffix: str) -> None:
    scene = _trimesh_scene()
    scene.export(tmp_path / f"scene{suffix}")
    asset = load_mesh(Path(f"scene{suffix}"), base_dir=tmp_path)
    assert asset.triangle_count == 36
    by_node = {p.node: p for p in asset.parts}
    assert set(by_node) == {"root_box", "child_box", "red_box"}
    for name, part in by_node.items():
        geometry_name = scene.graph[name][1]
        world, _ = scene.graph[name]
        expected = trimesh.transform_points(scene.geometry[geometry_name].vertices, world)
        # the file stores float32 vertices; the transforms are baked in float64
        np.testing.assert_allclose(part.positions, expected, atol=1e-6)
        tris = expected[part.indices]
        # trimesh's boxes wind outward; the baked triangles must too (counter-clockwise from outside)
        normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
        centre = expected.mean(axis=0)
        assert np.all(np.einsum("ij,ij->i", normals, tris.mean(axis=1) - centre) > 0)
    np.testing.assert_allclose(by_node["red_box"].colours, np.tile([1, 0, 0, 1], (len(by_node["red_box"].positions), 1)))
    assert asset.parts[0].base_colour == (1.0, 1.0, 1.0, 1.0) or asset.parts[0].texture is None
    bounds = scene.bounds
    np.testing.assert_allclose(asset.bbox_min, bounds[0], atol=1e-6)
    np.testing.assert_allclose(asset.bbox_max, bounds[1], atol=1e-6)
    if suffix == ".gltf":
        assert asset.resources and all(len(digest) == 64 for _, digest in asset.resources)


def test_trimesh_textured_model_is_srgb_decoded(tmp_path: Path) -> None:
    texels = np.zeros((4, 8, 4), dtype=np.uint8)
    texels[..., 0] = np.arange(8, dtype=np.uint8)[None, :] * 32
    texels[..., 1] = 128
    texels[..., 3] = np.array([255, 128, 64, 0], dtype=np.uint8)[:, None]
    positions, indices, uv = quad()
    material = trimesh.visual.material.PBRMaterial(baseColorTexture=Image.fromarray(texels, "RGBA"),
                                                   baseColorFactor=[255, 255, 255, 255], alphaMode="BLEND")
    mesh = trimesh.Trimesh(positions, indices, process=False,
                           visual=trimesh.visual.TextureVisuals(uv=np.column_stack([uv[:, 0], 1 - uv[:, 1]]),
                                                                material=material))
    mesh.export(tmp_path / "tex.glb")
    asset = load_mesh(Path("tex.glb"), base_dir=tmp_path)
    (part,) = asset.parts
    assert part.alpha_mode is AlphaMode.BLEND
    tex = part.texture
    assert tex is not None and tex.rgba_linear.shape == (4, 8, 4) and tex.rgba_linear.dtype == np.float32
    np.testing.assert_allclose(tex.rgba_linear[..., :3], srgb_to_linear(texels[..., :3] / 255.0), atol=1e-6)
    np.testing.assert_allclose(tex.rgba_linear[..., 3], texels[..., 3] / 255.0, atol=1e-7)  # alpha is not decoded
    # trimesh flips v when writing; glTF's v runs down from the image's top row, as psyop keeps it
    np.testing.assert_allclose(part.texcoords, uv, atol=1e-7)


def test_srgb_transfer_function_reference_values() -> None:
    # IEC 61966-2-1: 0.5 encodes 0.214041; the linear segment below 0.04045
    np.testing.assert_allclose(srgb_to_linear(np.array([0.0, 0.04, 0.5, 1.0])),
                               [0.0, 0.04 / 12.92, 0.21404114, 1.0], atol=1e-7)


def _hierarchy() -> RawGltf:
    raw = RawGltf()
    positions, indices, _ = quad(0.5)
    m = raw.mesh(positions, indices)
    strip = raw.mesh(positions[[0, 1, 3, 2]], None, mode=5)  # the same square as a strip, non-indexed
    leaf = raw.node(root=False, name="leaf", mesh=m, translation=[0.0, 0.0, -0.25],
                    rotation=[0.0, 0.0, np.sin(0.3), np.cos(0.3)])
    mirrored = raw.node(root=False, name="mirrored", mesh=strip, scale=[-1.0, 2.0, 1.0])
    matrix = np.eye(4)
    matrix[:3, 3] = [0.1, 0.2, 0.3]
    matrix[:3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]
    raw.node(name="parent", matrix=matrix.T.reshape(-1).tolist(), children=[leaf, mirrored])
    raw.node(name="other", mesh=m, translation=[2.0, 0, 0])
    return raw


@pytest.mark.parametrize("writer", ["glb", "gltf"])
def test_pygltflib_written_hierarchy_matches_trimeshs_scene_graph(tmp_path: Path, writer: str) -> None:
    raw = _hierarchy()
    path = raw.save_glb(tmp_path / "h.glb") if writer == "glb" else raw.save_gltf(tmp_path / "h.gltf")
    asset = load_mesh(Path(path.name), base_dir=tmp_path)
    theirs = trimesh.load(path, force="scene")
    assert sorted(p.node for p in asset.parts) == ["leaf", "mirrored", "other"]
    for part in asset.parts:
        world, geometry = theirs.graph[part.node]
        expected = trimesh.transform_points(theirs.geometry[geometry].vertices, world)
        np.testing.assert_allclose(part.positions, expected, atol=1e-7)
        # every baked triangle faces the direction the node's transform turns +z to (front faces kept)
        tris = part.positions[part.indices]
        face = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
        linear = world[:3, :3]
        facing = np.linalg.inv(linear).T @ [0, 0, 1]
        assert np.all(face @ facing > 0), part.node
    assert [p.triangle_count for p in asset.parts] == [2, 2, 2]


def test_node_selects_a_subtree_in_its_place(tmp_path: Path) -> None:
    _hierarchy().save_glb(tmp_path / "h.glb")
    whole = load_mesh(Path("h.glb"), base_dir=tmp_path)
    parent = load_mesh(Path("h.glb"), "parent", base_dir=tmp_path)
    leaf = load_mesh(Path("h.glb"), "leaf", base_dir=tmp_path)
    assert sorted(p.node for p in parent.parts) == ["leaf", "mirrored"]
    assert [p.node for p in leaf.parts] == ["leaf"] and leaf.node == "leaf"
    np.testing.assert_array_equal(leaf.parts[0].positions, next(p for p in whole.parts if p.node == "leaf").positions)
    assert leaf.record()["node"] == "leaf" and leaf.record()["triangle_count"] == 2


def test_normals_use_the_inverse_transpose(tmp_path: Path) -> None:
    raw = RawGltf()
    positions = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32)
    normal = np.array([1, 1, 0], dtype=np.float32) / np.sqrt(2)
    m = raw.mesh(positions, None, NORMAL=np.tile(normal, (3, 1)).astype(np.float32))
    raw.node(name="sheared", mesh=m, scale=[4.0, 1.0, 1.0])
    raw.save_glb(tmp_path / "n.glb")
    (part,) = load_mesh(Path("n.glb"), base_dir=tmp_path).parts
    expected = np.array([1 / 4, 1, 0]) / np.linalg.norm([1 / 4, 1, 0])
    np.testing.assert_allclose(part.normals, np.tile(expected, (3, 1)), atol=1e-6)
    assert part.normals.dtype == np.float32


def test_sampler_alpha_modes_and_blend_order(tmp_path: Path) -> None:
    raw = RawGltf()
    positions, indices, uv = quad()
    image = raw.image_png(np.full((2, 2, 4), 200, dtype=np.uint8))
    clamp = raw.texture(image, {"wrapS": 33071, "wrapT": 33648, "magFilter": 9728, "minFilter": 9729})
    repeat = raw.texture(image, {})
    blend = raw.material(alphaMode="BLEND", pbrMetallicRoughness={"baseColorFactor": [1, 0, 0, 0.5]})
    mask = raw.material(alphaMode="MASK", alphaCutoff=0.3, doubleSided=True,
                        pbrMetallicRoughness={"baseColorTexture": {"index": clamp}})
    opaque = raw.material(pbrMetallicRoughness={"baseColorTexture": {"index": repeat},
                                                "baseColorFactor": [0.5, 0.5, 0.5, 1]})
    for name, material in (("glass", blend), ("leaves", mask), ("wall", opaque)):
        raw.node(name=name, mesh=raw.mesh(positions, indices, material=material, TEXCOORD_0=uv))
    raw.save_glb(tmp_path / "m.glb")
    asset = load_mesh(Path("m.glb"), base_dir=tmp_path)
    assert [p.node for p in asset.parts] == ["leaves", "wall", "glass"]  # BLEND after the rest, else file order
    leaves, wall, glass = asset.parts
    assert (leaves.alpha_mode, leaves.alpha_cutoff, leaves.double_sided) == (AlphaMode.MASK, 0.3, True)
    assert (glass.alpha_mode, glass.base_colour, glass.texture) == (AlphaMode.BLEND, (1.0, 0.0, 0.0, 0.5), None)
    assert (wall.alpha_mode, wall.double_sided, wall.base_colour) == (AlphaMode.OPAQUE, False, (0.5, 0.5, 0.5, 1.0))
    assert leaves.texture is not None and wall.texture is not None
    assert (leaves.texture.wrap_s, leaves.texture.wrap_t) == (Wrap.CLAMP, Wrap.MIRROR)
    assert (leaves.texture.mag_filter, leaves.texture.min_filter) == (Filter.NEAREST, Filter.LINEAR)
    assert (wall.texture.wrap_s, wall.texture.mag_filter, wall.texture.min_filter) == (
        Wrap.REPEAT, Filter.LINEAR, Filter.LINEAR_MIPMAP)
    assert leaves.texture.key == wall.texture.key  # one image, one upload


def test_vertex_colours_normalized_ints_and_vec3(tmp_path: Path) -> None:
    raw = RawGltf()
    positions, indices, _ = quad()
    u16 = np.array([[65535, 0, 0, 65535], [0, 65535, 0, 32768], [0, 0, 65535, 0], [0, 0, 0, 65535]], dtype=np.uint16)
    raw.node(name="u16", mesh=raw.mesh(positions, indices, COLOR_0=u16))
    raw.node(name="f3", mesh=raw.mesh(positions, indices, COLOR_0=np.full((4, 3), 0.25, dtype=np.float32)))
    raw.save_glb(tmp_path / "c.glb")
    a, b = load_mesh(Path("c.glb"), base_dir=tmp_path).parts
    np.testing.assert_allclose(a.colours, u16 / 65535.0, atol=1e-7)
    np.testing.assert_allclose(b.colours, np.tile([0.25, 0.25, 0.25, 1.0], (4, 1)))


def test_data_uris_and_gltf_with_bin_and_png_files(tmp_path: Path) -> None:
    raw = RawGltf()
    positions, indices, uv = quad()
    raw.node(name="q", mesh=raw.mesh(positions, indices, material=raw.material(
        pbrMetallicRoughness={"baseColorTexture": {"index": 0}}), TEXCOORD_0=uv))
    doc = raw.document()
    doc["images"] = [{"uri": "textures/check%20er.png"}]
    doc["textures"] = [{"source": 0}]
    (tmp_path / "textures").mkdir()
    Image.fromarray(np.array([[[255, 0, 0, 255], [0, 0, 0, 255]]], dtype=np.uint8)).save(tmp_path / "textures" / "check er.png")
    doc["buffers"][0]["uri"] = "q.bin"
    (tmp_path / "q.bin").write_bytes(bytes(raw.blob))
    (tmp_path / "q.gltf").write_text(json.dumps(doc))
    asset = load_mesh(Path("q.gltf"), base_dir=tmp_path)
    assert [uri for uri, _ in asset.resources] == ["q.bin", "textures/check er.png"]
    assert asset.parts[0].texture is not None
    np.testing.assert_allclose(asset.parts[0].texture.rgba_linear[0, 0], [1, 0, 0, 1])

    import base64
    doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(bytes(raw.blob)).decode()
    png = (tmp_path / "textures" / "check er.png").read_bytes()
    doc["images"] = [{"uri": "data:image/png;base64," + base64.b64encode(png).decode()}]
    (tmp_path / "embedded.gltf").write_text(json.dumps(doc))
    embedded = load_mesh(Path("embedded.gltf"), base_dir=tmp_path)
    assert embedded.resources == ()
    np.testing.assert_array_equal(embedded.parts[0].positions, asset.parts[0].positions)
    np.testing.assert_array_equal(embedded.parts[0].texture.rgba_linear, asset.parts[0].texture.rgba_linear)


def test_mesh_files_loads_each_content_once(tmp_path: Path) -> None:
    _hierarchy().save_gltf(tmp_path / "h.gltf")
    files = MeshFiles(tmp_path)
    first = files.load("h.gltf")
    assert files.load("h.gltf") is first and files.loads == 1 and files.parses == 1
    leaf = files.load("h.gltf", "leaf")
    assert leaf is not first and files.loads == 2 and files.parses == 1  # a second node shares the file's parse
    raw = _hierarchy()
    raw.doc["nodes"][-1]["translation"] = [3.0, 0, 0]
    raw.save_gltf(tmp_path / "h.gltf")  # same .bin, edited .gltf
    assert files.load("h.gltf") is not first and files.loads == 3 and files.parses == 2
    again = files.load("h.gltf")
    edited = bytearray((tmp_path / "model.bin").read_bytes())
    edited[0] ^= 1  # a vertex moves
    (tmp_path / "model.bin").write_bytes(bytes(edited))
    assert files.load("h.gltf") is not again and files.loads == 4 and files.parses == 3
    assert files.load("h.gltf", "leaf") is not leaf and files.parses == 3  # the edited .bin: parsed again


@pytest.mark.parametrize("writer", ["glb", "gltf"])
def test_nodes_of_one_file_share_its_parse_and_equal_separate_loads(tmp_path: Path, writer: str) -> None:
    raw = _hierarchy()
    path = raw.save_glb(tmp_path / "h.glb") if writer == "glb" else raw.save_gltf(tmp_path / "h.gltf")
    files = MeshFiles(tmp_path)
    for node in ("leaf", "other", "parent", None):
        shared = files.load(path.name, node)
        alone = load_mesh(Path(path.name), node, base_dir=tmp_path)  # its own parse
        assert shared.sha256 == alone.sha256 and shared.resources == alone.resources
        assert [p.node for p in shared.parts] == [p.node for p in alone.parts]
        for a, b in zip(shared.parts, alone.parts):
            np.testing.assert_array_equal(a.positions, b.positions)
            np.testing.assert_array_equal(a.indices, b.indices)
        np.testing.assert_array_equal(shared.bbox_min, alone.bbox_min)
        np.testing.assert_array_equal(shared.bbox_max, alone.bbox_max)
    assert files.parses == 1 and files.loads == 4


def test_sparse_accessor_and_quantized_positions(tmp_path: Path) -> None:
    raw = RawGltf()
    positions, indices, _ = quad()
    m = raw.mesh(positions, indices)
    acc = raw.doc["accessors"][0]
    # sparse: vertex 2 moves to (2, 3, 0) on top of the stored positions
    acc["sparse"] = {"count": 1,
                     "indices": {"bufferView": raw.view(np.array([2], dtype=np.uint16).tobytes()), "componentType": 5123},
                     "values": {"bufferView": raw.view(np.array([2, 3, 0], dtype=np.float32).tobytes())}}
    del acc["min"], acc["max"]
    raw.node(name="sparse", mesh=m)
    # KHR_mesh_quantization: int16 positions, not normalized, scaled by the node
    raw.doc["meshes"].append({"primitives": [{"attributes": {"POSITION": raw.accessor(
        np.array([[0, 0, 0], [1000, 0, 0], [0, 1000, 0]], dtype=np.int16))}}]})
    q = len(raw.doc["meshes"]) - 1
    raw.node(name="quantized", mesh=q, scale=[0.001, 0.001, 0.001])
    raw.doc["extensionsUsed"] = raw.doc["extensionsRequired"] = ["KHR_mesh_quantization"]
    doc = raw.document()
    (tmp_path / "s.bin").write_bytes(bytes(raw.blob))
    doc["buffers"][0]["uri"] = "s.bin"
    (tmp_path / "s.gltf").write_text(json.dumps(doc))
    sparse, quantized = load_mesh(Path("s.gltf"), base_dir=tmp_path).parts
    expected = positions.astype(np.float64)
    expected[2] = [2, 3, 0]
    np.testing.assert_array_equal(sparse.positions, expected)
    np.testing.assert_allclose(quantized.positions, [[0, 0, 0], [1, 0, 0], [0, 1, 0]], atol=1e-12)
    theirs = trimesh.load(tmp_path / "s.gltf", force="scene", process=False)
    world, geometry = theirs.graph["quantized"]
    np.testing.assert_allclose(quantized.positions, trimesh.transform_points(theirs.geometry[geometry].vertices, world))
