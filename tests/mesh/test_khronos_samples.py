"""Khronos sample models (tests/mesh/data/README.md): files written by other tools load as trimesh reads them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from psyop.mesh import AlphaMode, load_mesh

DATA = Path(__file__).parent / "data"


def test_box_from_collada2gltf() -> None:
    asset = load_mesh(Path("Box.gltf"), base_dir=DATA)
    (part,) = asset.parts
    assert asset.triangle_count == 12 and asset.resources == ()
    np.testing.assert_allclose(asset.bbox_min, [-0.5] * 3)
    np.testing.assert_allclose(asset.bbox_max, [0.5] * 3)
    assert part.base_colour == (0.800000011920929, 0.0, 0.0, 1.0) and part.alpha_mode is AlphaMode.OPAQUE
    # the root's Y-up -> Z-up matrix is baked into positions and normals alike: each stored normal
    # is the unit outward normal of its triangles, which wind counter-clockwise seen from outside
    tris = part.positions[part.indices]
    face = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    face /= np.linalg.norm(face, axis=1, keepdims=True)
    np.testing.assert_allclose(part.normals[part.indices[:, 0]], face, atol=1e-6)
    assert np.all(np.einsum("ij,ij->i", face, tris.mean(axis=1)) > 0)
    theirs = trimesh.load(DATA / "Box.gltf", force="scene")
    np.testing.assert_allclose(np.sort(part.positions, axis=0), np.sort(theirs.to_geometry().vertices, axis=0),
                               atol=1e-7)


def test_triangle_without_indices() -> None:
    (part,) = load_mesh(Path("TriangleWithoutIndices.gltf"), base_dir=DATA).parts
    np.testing.assert_array_equal(part.indices, [[0, 1, 2]])
    np.testing.assert_array_equal(part.positions, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    assert part.normals is None and part.texcoords is None and part.base_colour == (1.0, 1.0, 1.0, 1.0)


def test_box_textured_texture_sampler_and_uvs_match_trimesh() -> None:
    from psyop.mesh import Filter, Wrap
    from psyop.mesh.load import srgb_to_linear

    asset = load_mesh(Path("BoxTextured.gltf"), base_dir=DATA)
    (part,) = asset.parts  # the empty node {} contributes nothing
    tex = part.texture
    assert tex is not None and tex.rgba_linear.shape == (211, 211, 4)
    assert (tex.wrap_s, tex.wrap_t, tex.mag_filter, tex.min_filter) == (Wrap.REPEAT, Wrap.REPEAT, Filter.LINEAR,
                                                                         Filter.LINEAR_MIPMAP)
    theirs = next(iter(trimesh.load(DATA / "BoxTextured.gltf", force="scene").geometry.values()))
    image = np.asarray(theirs.visual.material.baseColorTexture.convert("RGBA"), dtype=np.float64) / 255.0
    np.testing.assert_allclose(tex.rgba_linear[..., :3], srgb_to_linear(image[..., :3]), atol=1e-6)
    assert part.texcoords is not None and float(part.texcoords[:, 0].max()) == 6.0  # u repeats six times
    # trimesh (unprocessed: vertices in file order) keeps uv with v up, 1 - glTF's v
    scene = trimesh.load(DATA / "BoxTextured.gltf", force="scene", process=False)
    (name,) = scene.geometry
    world, _ = scene.graph[scene.graph.geometry_nodes[name][0]]
    np.testing.assert_allclose(part.positions, trimesh.transform_points(scene.geometry[name].vertices, world), atol=1e-7)
    uv = scene.geometry[name].visual.uv
    np.testing.assert_allclose(part.texcoords, np.column_stack([uv[:, 0], 1 - uv[:, 1]]), atol=1e-6)
