"""Writing glTF 2.0 files by hand with pygltflib's document model, for tests that need exact control.

Each test states the JSON it means (nodes, accessors, materials, samplers) and this module packs
the arrays into one buffer and saves a ``.glb`` (pygltflib's writer) or a ``.gltf`` + ``.bin``.
Corrupting a field afterwards is how the bad-input tests build their files.
"""

from __future__ import annotations

import copy
import io
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

_COMPONENT = {np.dtype("<f4"): 5126, np.dtype("<u4"): 5125, np.dtype("<u2"): 5123, np.dtype("<u1"): 5121,
              np.dtype("<i2"): 5122, np.dtype("<i1"): 5120}
_TYPE = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}


@dataclass
class RawGltf:
    """A glTF document under construction: ``doc`` is the JSON, ``blob`` the binary buffer."""

    doc: dict[str, Any] = field(default_factory=lambda: {
        "asset": {"version": "2.0", "generator": "psyop tests (pygltflib)"},
        "scene": 0, "scenes": [{"nodes": []}], "nodes": [], "meshes": [], "accessors": [],
        "bufferViews": [], "buffers": []})
    blob: bytearray = field(default_factory=bytearray)

    def view(self, data: bytes) -> int:
        while len(self.blob) % 4:
            self.blob.append(0)
        self.doc["bufferViews"].append({"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)})
        self.blob.extend(data)
        return len(self.doc["bufferViews"]) - 1

    def accessor(self, values: np.ndarray, *, normalized: bool = False) -> int:
        values = np.ascontiguousarray(values)
        width = 1 if values.ndim == 1 else values.shape[1]
        acc: dict[str, Any] = {"bufferView": self.view(values.tobytes()), "componentType": _COMPONENT[values.dtype],
                               "count": int(values.shape[0]), "type": _TYPE[width]}
        if normalized:
            acc["normalized"] = True
        if values.dtype == np.float32 and width == 3 and np.all(np.isfinite(values)):
            acc["min"] = values.min(axis=0).tolist()
            acc["max"] = values.max(axis=0).tolist()
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def mesh(self, positions: np.ndarray, indices: np.ndarray | None = None, *, material: int | None = None,
             mode: int | None = None, **attributes: np.ndarray) -> int:
        attrs = {"POSITION": self.accessor(np.asarray(positions, dtype=np.float32))}
        for name, values in attributes.items():
            normalized = values.dtype.kind in "ui"
            attrs[name] = self.accessor(values, normalized=normalized)
        primitive: dict[str, Any] = {"attributes": attrs}
        if indices is not None:
            primitive["indices"] = self.accessor(np.asarray(indices).reshape(-1))
        if material is not None:
            primitive["material"] = material
        if mode is not None:
            primitive["mode"] = mode
        self.doc["meshes"].append({"primitives": [primitive]})
        return len(self.doc["meshes"]) - 1

    def node(self, *, root: bool = True, **fields: Any) -> int:
        self.doc["nodes"].append(fields)
        index = len(self.doc["nodes"]) - 1
        if root:
            self.doc["scenes"][0]["nodes"].append(index)
        return index

    def image_png(self, rgba: np.ndarray) -> int:
        from PIL import Image

        out = io.BytesIO()
        Image.fromarray(np.asarray(rgba, dtype=np.uint8)).save(out, format="PNG")
        self.doc.setdefault("images", []).append({"bufferView": self.view(out.getvalue()), "mimeType": "image/png"})
        return len(self.doc["images"]) - 1

    def material(self, **fields: Any) -> int:
        self.doc.setdefault("materials", []).append(fields)
        return len(self.doc["materials"]) - 1

    def texture(self, image: int, sampler: dict[str, int] | None = None) -> int:
        tex: dict[str, Any] = {"source": image}
        if sampler is not None:
            self.doc.setdefault("samplers", []).append(sampler)
            tex["sampler"] = len(self.doc["samplers"]) - 1
        self.doc.setdefault("textures", []).append(tex)
        return len(self.doc["textures"]) - 1

    def document(self) -> dict[str, Any]:
        doc = copy.deepcopy(self.doc)
        doc["buffers"] = [{"byteLength": len(self.blob)}]
        return {k: v for k, v in doc.items() if v != []}

    def save_glb(self, path: Path) -> Path:
        import pygltflib

        gltf = pygltflib.GLTF2.from_json(json.dumps(self.document()))
        gltf.set_binary_blob(bytes(self.blob))
        gltf.save_binary(str(path))
        return path

    def save_gltf(self, path: Path, bin_name: str = "model.bin") -> Path:
        """A ``.gltf`` whose buffer is the file ``bin_name`` beside it (images stay in buffer views)."""
        doc = self.document()
        doc["buffers"][0]["uri"] = bin_name
        (path.parent / bin_name).write_bytes(bytes(self.blob))
        path.write_text(json.dumps(doc, indent=1))
        return path


def quad(size: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A square in the z = 0 plane facing +z: positions, (2, 3) indices, texcoords (v down from the top row)."""
    h = size / 2
    positions = np.array([[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]], dtype=np.float32)
    indices = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.uint16)
    texcoords = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], dtype=np.float32)
    return positions, indices, texcoords
