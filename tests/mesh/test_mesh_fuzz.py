"""Damaged models never end in a traceback: every corruption is a UserError or still a valid model."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from raw_gltf import RawGltf, quad

from psyop.errors import UserError
from psyop.mesh import MeshAsset, load_mesh


def _model() -> RawGltf:
    raw = RawGltf()
    positions, indices, uv = quad()
    image = raw.image_png(np.full((2, 2, 4), 99, dtype=np.uint8))
    material = raw.material(alphaMode="MASK", pbrMetallicRoughness={"baseColorTexture": {"index": raw.texture(image, {})}})
    child = raw.node(root=False, name="child", mesh=raw.mesh(positions, indices, material=material, TEXCOORD_0=uv),
                     rotation=[0, 0.6, 0, 0.8])
    raw.node(name="root", children=[child], scale=[1, 2, 3])
    return raw


def _loads_or_refuses(folder: Path, name: str) -> None:
    try:
        asset = load_mesh(Path(name), base_dir=folder)
    except UserError as error:
        assert "\n" not in str(error) and name in str(error)
    else:
        assert isinstance(asset, MeshAsset) and asset.triangle_count > 0


@settings(max_examples=150)
@given(edits=st.lists(st.tuples(st.integers(0, 10_000), st.integers(0, 255)), min_size=1, max_size=4),
       cut=st.none() | st.integers(0, 10_000))
def test_corrupted_glb_bytes(tmp_path_factory, edits: list[tuple[int, int]], cut: int | None) -> None:  # type: ignore[no-untyped-def]
    folder = tmp_path_factory.mktemp("glb")
    data = bytearray(_model().save_glb(folder / "m.glb").read_bytes())
    for position, value in edits:
        data[position % len(data)] = value
    if cut is not None:
        data = data[: cut % len(data)]
    (folder / "m.glb").write_bytes(bytes(data))
    _loads_or_refuses(folder, "m.glb")


_VALUES = st.one_of(st.none(), st.booleans(), st.integers(-3, 70_000), st.floats(allow_nan=True), st.text(max_size=4),
                    st.lists(st.integers(-1, 5), max_size=5), st.dictionaries(st.sampled_from(["index", "uri"]), st.integers(-1, 3)))


@settings(max_examples=150)
@given(data=st.data())
def test_wrong_json_values(tmp_path_factory, data: st.DataObject) -> None:  # type: ignore[no-untyped-def]
    folder = tmp_path_factory.mktemp("gltf")
    _model().save_gltf(folder / "m.gltf")
    doc = json.loads((folder / "m.gltf").read_text())
    paths = []
    for key, value in doc.items():
        if isinstance(value, list):
            for i, entry in enumerate(value):
                if isinstance(entry, dict):
                    paths += [(key, i, field) for field in entry]
    for key, index, field in data.draw(st.lists(st.sampled_from(paths), min_size=1, max_size=3)):
        doc[key][index][field] = data.draw(_VALUES)
    (folder / "m.gltf").write_text(json.dumps(doc))
    _loads_or_refuses(folder, "m.gltf")
