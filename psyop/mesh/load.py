"""Loading a glTF 2.0 model (``.gltf`` + ``.bin`` + images, ``data:`` URIs, or ``.glb``) into a :class:`MeshAsset`.

pygltflib parses the JSON into typed dataclasses; everything that touches bytes is done here
with explicit bounds: the GLB container, URIs (which must stay inside the model's folder),
accessors (checked against their buffer views), images (decoded with Pillow). Every refusal
is one :class:`~psyop.errors.UserError` naming the file, the mesh/primitive or node index,
and the fix, raised at load time so ``psyop validate`` reports it (docs/rendering.md,
"Meshes: loading").

What is read: the scene's node hierarchy (``scene``, else scene 0, else every root node) with
its TRS or matrix transforms baked into the vertices in float64; TRIANGLES (also strips and
fans, converted to lists), indexed or not; POSITION, NORMAL (by the inverse-transpose),
TEXCOORD_0, COLOR_0; the material's base-colour factor and texture (sRGB-decoded, alpha kept)
with its sampler, ``alphaMode`` and ``alphaCutoff``, ``doubleSided``. What is not drawn is
refused rather than dropped: points and lines, skins, morph targets with non-zero weights, a
base-colour texture on another texture coordinate set or with ``KHR_texture_transform``, and
every required extension except the two psyop honours (``KHR_materials_unlit``: psyop's
default shading is unlit anyway; ``KHR_mesh_quantization``: the accessor reader takes any
component type). Animations, cameras, lights and the other PBR inputs (metallic, roughness,
normal, occlusion and emissive maps) are not part of a psychophysics stimulus and are ignored.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import io
import json
import re
import struct
import warnings
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from urllib.parse import unquote

import numpy as np

from psyop.errors import UserError
from psyop.input_files import InputFile
from psyop.limits import MAX_DATA_URI_BYTES, MAX_MESH_FILE_BYTES, MAX_MESH_TRIANGLES, MAX_TEXTURE_SIDE_PX
from psyop.mesh.asset import AlphaMode, Filter, MeshAsset, MeshPart, MeshTexture, Wrap

#: required extensions psyop honours (see the module docstring); any other is refused by name
SUPPORTED_REQUIRED_EXTENSIONS: frozenset[str] = frozenset({"KHR_materials_unlit", "KHR_mesh_quantization"})

_GLB_MAGIC = b"glTF"
_CHUNK_JSON = 0x4E4F534A
_CHUNK_BIN = 0x004E4942

_COMPONENTS: dict[int, np.dtype] = {
    5120: np.dtype("<i1"), 5121: np.dtype("<u1"), 5122: np.dtype("<i2"),
    5123: np.dtype("<u2"), 5125: np.dtype("<u4"), 5126: np.dtype("<f4"),
}
_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}
_MODES = {0: "POINTS", 1: "LINES", 2: "LINE_LOOP", 3: "LINE_STRIP", 4: "TRIANGLES", 5: "TRIANGLE_STRIP",
          6: "TRIANGLE_FAN"}
_WRAPS = {10497: Wrap.REPEAT, 33071: Wrap.CLAMP, 33648: Wrap.MIRROR}
#: glTF's minification filters; every mipmapped one (9984-9987) is drawn trilinear (LINEAR_MIPMAP)
_MIN_FILTERS = {9728: Filter.NEAREST, 9729: Filter.LINEAR, 9984: Filter.LINEAR_MIPMAP, 9985: Filter.LINEAR_MIPMAP,
                9986: Filter.LINEAR_MIPMAP, 9987: Filter.LINEAR_MIPMAP}
_MAG_FILTERS = {9728: Filter.NEAREST, 9729: Filter.LINEAR}
#: the most elements an accessor may hold (three indices per triangle of the largest model)
_MAX_ACCESSOR_COUNT = 3 * MAX_MESH_TRIANGLES
_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*:")
_IMAGE_FORMATS = {"PNG": "image/png", "JPEG": "image/jpeg"}


def _model_file(path: Path) -> InputFile:
    return InputFile(what=f"model {path.name}", give="give a glTF 2.0 .gltf or .glb file",
                     max_bytes=MAX_MESH_FILE_BYTES,
                     typical="simplify the model or split it into several files",
                     not_found="model file {path} not found; paths are relative to the protocol file")


def sha256_hex(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def srgb_to_linear(encoded: np.ndarray) -> np.ndarray:
    """The sRGB transfer function inverted (IEC 61966-2-1), for values in [0, 1]."""
    c = np.asarray(encoded, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


# ---- the container --------------------------------------------------------------------------

@dataclass(frozen=True)
class _Container:
    """A model's JSON document and its GLB binary chunk (None for a ``.gltf``)."""

    document: dict  # type: ignore[type-arg]
    glb_bin: bytes | None


def _parse_glb(raw: bytes, where: str) -> _Container:
    fix = "re-export it as glTF 2.0 binary (.glb)"
    if len(raw) < 12:
        raise UserError(f"{where}: truncated .glb ({len(raw)} bytes, shorter than the 12-byte header); {fix}")
    magic, version, length = raw[:4], *struct.unpack("<II", raw[4:12])
    if magic != _GLB_MAGIC:
        raise UserError(f"{where}: not a .glb file (magic {magic!r}, expected b'glTF'); {fix}")
    if version != 2:
        raise UserError(f"{where}: .glb container version {version}, psyop reads version 2 (glTF 2.0); {fix}")
    if length != len(raw):
        state = "truncated" if length > len(raw) else "corrupt"
        raise UserError(f"{where}: {state} .glb: its header says {length} bytes, the file has {len(raw)}; {fix}")
    offset, chunks = 12, list[tuple[int, bytes]]()
    while offset < length:
        if offset + 8 > length:
            raise UserError(f"{where}: corrupt .glb: a chunk header at byte {offset} runs past the end; {fix}")
        chunk_length, chunk_type = struct.unpack("<II", raw[offset:offset + 8])
        if offset + 8 + chunk_length > length:
            raise UserError(f"{where}: truncated .glb: chunk {len(chunks)} ({chunk_length} bytes at byte "
                            f"{offset + 8}) runs past the end of the file; {fix}")
        chunks.append((chunk_type, raw[offset + 8:offset + 8 + chunk_length]))
        offset += 8 + chunk_length
    if not chunks or chunks[0][0] != _CHUNK_JSON:
        raise UserError(f"{where}: corrupt .glb: the first chunk is not JSON; {fix}")
    glb_bin = chunks[1][1] if len(chunks) > 1 and chunks[1][0] == _CHUNK_BIN else None
    return _Container(_parse_json(chunks[0][1], where), glb_bin)


def _parse_json(raw: bytes, where: str) -> dict:  # type: ignore[type-arg]
    try:
        document = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise UserError(f"{where}: not glTF 2.0 JSON ({error}); give a .gltf or .glb file exported as glTF 2.0") from None
    if not isinstance(document, dict):
        raise UserError(f"{where}: not glTF 2.0 JSON (the document is not an object); give a .gltf or .glb file")
    return document


# ---- URIs -----------------------------------------------------------------------------------

class _Resources:
    """Reads a model's buffers and images: its GLB chunk, ``data:`` URIs, or files in its folder."""

    def __init__(self, model: Path, glb_bin: bytes | None) -> None:
        self.model = model
        self.folder = model.parent
        self.glb_bin = glb_bin
        self.read: dict[str, str] = {}  # relative uri -> sha256 of each external file read
        self._cache: dict[str, bytes] = {}

    def uri(self, uri: object, what: str) -> bytes:
        where = f"{self.model}: {what}"
        if not isinstance(uri, str) or not uri:
            raise UserError(f"{where} has no uri; re-export the model")
        if uri.startswith("data:"):
            return self._data_uri(uri, where)
        relative = unquote(uri)
        if _SCHEME.match(uri) or uri.startswith(("/", "\\")) or relative.startswith(("/", "\\")):
            raise UserError(f"{where}: uri '{uri[:80]}' is not a path inside the model's folder (no schemes such as "
                            "file: or http:, no absolute paths); copy the file next to the model and name it relatively")
        parts = PurePosixPath(relative.replace("\\", "/")).parts
        if ".." in parts or "\x00" in relative:
            raise UserError(f"{where}: uri '{uri[:80]}' leaves the model's folder; copy the file next to the "
                            "model (or into a folder below it) and name it relatively")
        target = self.folder.joinpath(*parts)
        try:
            inside = target.resolve().is_relative_to(self.folder.resolve())
        except OSError:
            inside = False
        if not inside:
            raise UserError(f"{where}: uri '{uri[:80]}' resolves outside the model's folder (a link?); copy the "
                            "file next to the model")
        if relative not in self._cache:
            reader = InputFile(what=f"{self.model.name}'s {what} ({relative})",
                               give=f"{what} of {self.model.name} must be a file",
                               max_bytes=MAX_MESH_FILE_BYTES, typical="simplify the model or its textures",
                               not_found=f"{self.model}: {what}'s file '{relative}' not found (looked for {{path}}); "
                                         "copy it next to the model, or export a single .glb")
            data = reader.read_bytes(target)
            self._cache[relative] = data
            self.read[relative] = sha256_hex(data)
        return self._cache[relative]

    @staticmethod
    def _data_uri(uri: str, where: str) -> bytes:
        if len(uri) > MAX_DATA_URI_BYTES:
            raise UserError(f"{where}: data: URI of {len(uri)} bytes, over the {MAX_DATA_URI_BYTES} byte limit; "
                            "export the model as .glb (or with a separate .bin)")
        header, comma, payload = uri.partition(",")
        if not comma or not header.endswith(";base64"):
            raise UserError(f"{where}: data: URI is not base64 ('data:<type>;base64,...', as glTF requires); re-export the model")
        try:
            return base64.b64decode(payload, validate=True)
        except (binascii.Error, ValueError) as error:
            raise UserError(f"{where}: data: URI is not valid base64 ({error}); re-export the model") from None


# ---- the loader -----------------------------------------------------------------------------

def _listed(document: dict, key: str) -> list:  # type: ignore[type-arg]
    value = document.get(key, [])
    return value if isinstance(value, list) else []


class _Reader:
    """One model's parse: pygltflib's typed document, its bytes, and the checks, located in messages."""

    def __init__(self, path: Path, raw: bytes) -> None:
        import pygltflib  # type: ignore[import-untyped]

        self.path = path
        self.sha256 = sha256_hex(raw)
        where = str(path)
        suffix = path.suffix.lower()
        if raw[:4] == _GLB_MAGIC or suffix == ".glb":
            container = _parse_glb(raw, where)
        elif suffix == ".gltf":
            container = _Container(_parse_json(raw, where), None)
        else:
            raise UserError(f"{where}: not a glTF model (the name ends '{path.suffix}'); give a .gltf or .glb file")
        self.check_asset(container.document)
        try:
            with warnings.catch_warnings():  # dataclasses_json warns of each optional field left out
                warnings.simplefilter("ignore", RuntimeWarning)
                self.gltf = pygltflib.GLTF2.from_dict(container.document, infer_missing=True)
            for mesh in self.gltf.meshes:  # as pygltflib's own from_json does: attributes are free-form
                for primitive in mesh.primitives:
                    if isinstance(primitive.attributes, dict):
                        primitive.attributes = pygltflib.Attributes(**primitive.attributes)
        except Exception as error:  # noqa: BLE001 - any schema mismatch is the user's input
            raise UserError(f"{where}: not a valid glTF 2.0 document ({type(error).__name__}: {error}); "
                            "re-export the model as glTF 2.0") from None
        self.document = container.document
        self.resources = _Resources(path, container.glb_bin)
        self._buffers: dict[int, bytes] = {}
        self._textures: dict[int, MeshTexture] = {}
        self.used: set[tuple[str, int]] = set()  # ("buffer" | "texture", index) read by the current selection

    def fail(self, where: str, message: str) -> UserError:
        return UserError(f"{self.path}: {where}: {message}")

    def check_asset(self, document: dict) -> None:  # type: ignore[type-arg]
        asset = document.get("asset")
        version = str(asset.get("version", "")) if isinstance(asset, dict) else ""
        if not version.startswith("2."):
            raise UserError(f"{self.path}: glTF version '{version or 'missing'}', psyop reads glTF 2.0; "
                            "re-export the model as glTF 2.0")
        min_version = str(asset.get("minVersion", "2.0")) if isinstance(asset, dict) else "2.0"
        if min_version != "2.0":
            raise UserError(f"{self.path}: the model needs glTF {min_version} (asset.minVersion), psyop reads glTF 2.0")
        required = [str(name) for name in _listed(document, "extensionsRequired")]
        unsupported = [name for name in required if name not in SUPPORTED_REQUIRED_EXTENSIONS]
        if unsupported:
            raise UserError(f"{self.path}: requires glTF extension(s) psyop does not read: {', '.join(unsupported)}; "
                            "re-export without compression (Draco, meshopt) or KTX2/Basis textures (PNG or JPEG)")

    # -- buffers and accessors --------------------------------------------------------------
    def item(self, items: list, index: object, what: str, where: str):  # type: ignore[no-untyped-def,type-arg]
        if not isinstance(index, int) or isinstance(index, bool) or not 0 <= index < len(items or []):
            raise self.fail(where, f"{what} {index!r} does not exist (the file has {len(items or [])}); re-export the model")
        return items[index]

    def buffer(self, index: int, where: str) -> bytes:
        self.used.add(("buffer", index))
        if index not in self._buffers:
            buffer = self.item(self.gltf.buffers, index, "buffer", where)
            if buffer.uri is None:
                if index != 0 or self.resources.glb_bin is None:
                    raise self.fail(where, f"buffer {index} has no uri and there is no .glb binary chunk; re-export the model")
                data = self.resources.glb_bin
            else:
                data = self.resources.uri(buffer.uri, f"buffer {index}")
            length = buffer.byteLength
            if not isinstance(length, int) or len(data) < length:
                raise self.fail(where, f"buffer {index} has {len(data)} bytes, its byteLength says {length}: the file "
                                       "is truncated or not this model's; re-export the model")
            self._buffers[index] = data
        return self._buffers[index]

    def view_bytes(self, index: int, where: str) -> tuple[bytes, int, int, int | None]:
        """(buffer bytes, view start, view length, byteStride) of buffer view ``index``, bounds-checked."""
        view = self.item(self.gltf.bufferViews, index, "bufferView", where)
        data = self.buffer(view.buffer, where)
        start, length = view.byteOffset or 0, view.byteLength
        if not isinstance(length, int) or start < 0 or start + length > len(data):
            raise self.fail(where, f"bufferView {index} ({start}+{length} bytes) runs past its buffer's "
                                   f"{len(data)} bytes; re-export the model")
        return data, start, length, view.byteStride

    def accessor(self, index: object, where: str, *, widths: tuple[str, ...]) -> np.ndarray:
        """Accessor ``index`` as an (count, width) float64 or integer array (normalized ints scaled)."""
        acc = self.item(self.gltf.accessors, index, "accessor", where)
        where = f"{where}, accessor {index}"
        if acc.type not in widths:
            raise self.fail(where, f"type {acc.type}, expected {' or '.join(widths)}; re-export the model")
        dtype = _COMPONENTS.get(acc.componentType)
        if dtype is None:
            raise self.fail(where, f"componentType {acc.componentType} is not a glTF component type; re-export the model")
        width, count = _WIDTHS[acc.type], acc.count
        if not isinstance(count, int) or count < 0:
            raise self.fail(where, f"count {count!r} is not a count; re-export the model")
        if count > _MAX_ACCESSOR_COUNT:  # an accessor without a bufferView is zeros: bound it before allocating
            raise self.fail(where, f"{count} elements, more than a model of {MAX_MESH_TRIANGLES} triangles "
                                   "needs; decimate the model")
        element = dtype.itemsize * width
        if acc.bufferView is None:
            values = np.zeros((count, width), dtype=dtype)
        else:
            data, start, length, stride = self.view_bytes(acc.bufferView, where)
            stride = stride or element
            offset = start + (acc.byteOffset or 0)
            end = offset + stride * (count - 1) + element if count else offset
            if stride < element or end > start + length:
                raise self.fail(where, f"{count} x {element}-byte elements (stride {stride}) do not fit its "
                                       f"bufferView; the file is corrupt, re-export the model")
            values = np.ndarray((count, width), dtype=dtype, buffer=data, offset=offset,
                                strides=(stride, dtype.itemsize)).copy()
        if acc.sparse is not None and acc.sparse.count:
            values = values.copy()
            sparse = acc.sparse
            sparse_dtype = _COMPONENTS.get(sparse.indices.componentType)
            if sparse_dtype is None or sparse_dtype.kind != "u":
                raise self.fail(where, "sparse indices are not unsigned integers; re-export the model")
            slots = self._view_array(sparse.indices.bufferView, sparse.indices.byteOffset, sparse_dtype,
                                     sparse.count, 1, where)[:, 0].astype(np.int64)
            if slots.size and (slots.max() >= count):
                raise self.fail(where, f"sparse index {int(slots.max())} is past the accessor's {count} elements")
            values[slots] = self._view_array(sparse.values.bufferView, sparse.values.byteOffset, dtype,
                                             sparse.count, width, where)
        if acc.normalized:
            if dtype.kind == "f":
                raise self.fail(where, "a float accessor cannot be normalized; re-export the model")
            scale = float(np.iinfo(dtype).max)
            return np.maximum(values.astype(np.float64) / scale, -1.0)
        if dtype.kind == "f":
            return values.astype(np.float64)
        return values

    def _view_array(self, view: int, byte_offset: int | None, dtype: np.dtype, count: int, width: int,
                    where: str) -> np.ndarray:
        data, start, length, _ = self.view_bytes(view, where)
        offset = start + (byte_offset or 0)
        if offset + count * width * dtype.itemsize > start + length:
            raise self.fail(where, "sparse data runs past its bufferView; re-export the model")
        return np.frombuffer(data, dtype=dtype, count=count * width, offset=offset).reshape(count, width)

    # -- textures ---------------------------------------------------------------------------
    def texture(self, index: int, where: str) -> MeshTexture:
        self.used.add(("texture", index))
        if index in self._textures:
            return self._textures[index]
        texture = self.item(self.gltf.textures, index, "texture", where)
        if texture.source is None:
            raise self.fail(where, f"texture {index} has no PNG/JPEG source (a KTX2/WebP-only texture?); "
                                   "re-export with PNG or JPEG textures")
        image_index = texture.source
        image = self.item(self.gltf.images, image_index, "image", where)
        what = f"image {image_index}"
        if image.uri is not None:
            data = self.resources.uri(image.uri, what)
            name = image.uri if not image.uri.startswith("data:") else "a data: URI"
        elif image.bufferView is not None:
            buf, start, length, _ = self.view_bytes(image.bufferView, f"{where}, {what}")
            data, name = buf[start:start + length], f"bufferView {image.bufferView}"
        else:
            raise self.fail(where, f"{what} has neither uri nor bufferView; re-export the model")
        rgba = decode_texture_rgba(data, f"{self.path}: {what} ({name[:80]})")
        wrap_s, wrap_t, mag, min_ = Wrap.REPEAT, Wrap.REPEAT, Filter.LINEAR, Filter.LINEAR_MIPMAP
        if texture.sampler is not None:
            sampler = self.item(self.gltf.samplers, texture.sampler, "sampler", where)
            try:
                wrap_s = _WRAPS[sampler.wrapS if sampler.wrapS is not None else 10497]
                wrap_t = _WRAPS[sampler.wrapT if sampler.wrapT is not None else 10497]
                mag = _MAG_FILTERS[sampler.magFilter] if sampler.magFilter is not None else Filter.LINEAR
                min_ = _MIN_FILTERS[sampler.minFilter] if sampler.minFilter is not None else Filter.LINEAR_MIPMAP
            except KeyError as error:
                raise self.fail(where, f"sampler {texture.sampler} has the unknown GL constant {error}; "
                                       "re-export the model") from None
        result = MeshTexture(key=f"{self.sha256}:image{image_index}", rgba_linear=rgba, wrap_s=wrap_s,
                             wrap_t=wrap_t, mag_filter=mag, min_filter=min_)
        self._textures[index] = result
        return result

    # -- materials --------------------------------------------------------------------------
    def material(self, index: int | None, where: str
                 ) -> tuple[tuple[float, float, float, float], MeshTexture | None, AlphaMode, float, bool]:
        if index is None:  # glTF's default material: white, opaque, single-sided
            return (1.0, 1.0, 1.0, 1.0), None, AlphaMode.OPAQUE, 0.5, False
        material = self.item(self.gltf.materials, index, "material", where)
        where = f"{where}, material {index}"
        pbr = material.pbrMetallicRoughness
        factor = list(pbr.baseColorFactor) if pbr is not None and pbr.baseColorFactor is not None else [1.0] * 4
        colour = np.asarray(factor, dtype=np.float64)
        if colour.shape != (4,) or not np.all(np.isfinite(colour)) or colour.min() < 0 or colour.max() > 1:
            raise self.fail(where, f"baseColorFactor {factor} is not 4 numbers in [0, 1]; fix the material")
        texture = None
        if pbr is not None and pbr.baseColorTexture is not None:
            info = pbr.baseColorTexture
            if (info.texCoord or 0) != 0:
                raise self.fail(where, f"the base-colour texture uses TEXCOORD_{info.texCoord}, psyop reads "
                                       "TEXCOORD_0; re-export with one UV set")
            if "KHR_texture_transform" in (info.extensions or {}):
                raise self.fail(where, "the base-colour texture uses KHR_texture_transform, which psyop does not "
                                       "apply; bake the transform into the UVs")
            texture = self.texture(info.index, where)
        try:
            mode = AlphaMode(material.alphaMode or "OPAQUE")
        except ValueError:
            raise self.fail(where, f"alphaMode '{material.alphaMode}' is not OPAQUE, MASK or BLEND") from None
        cutoff = 0.5 if material.alphaCutoff is None else float(material.alphaCutoff)
        if not 0.0 <= cutoff <= 1.0:
            raise self.fail(where, f"alphaCutoff {cutoff} is outside [0, 1]; fix the material")
        rgba = (float(colour[0]), float(colour[1]), float(colour[2]), float(colour[3]))
        return rgba, texture, mode, cutoff, bool(material.doubleSided)

    # -- meshes -----------------------------------------------------------------------------
    def parts(self, node_index: int, node_name: str, matrix: np.ndarray) -> list[MeshPart]:
        node = self.gltf.nodes[node_index]
        where = f"node {node_index} ('{node_name}')"
        if node.skin is not None:
            raise self.fail(where, "is a skinned mesh; psyop draws static meshes: apply the pose in your "
                                   "modelling tool and export without the armature")
        mesh = self.item(self.gltf.meshes, node.mesh, "mesh", where)
        if np.linalg.det(matrix[:3, :3]) == 0:  # a zero scale hides a node (glTF's idiom): nothing to draw
            return []
        raw_node = _listed(self.document, "nodes")[node_index]
        node_weights = raw_node.get("weights") if isinstance(raw_node, dict) else None
        weights = list(node_weights) if isinstance(node_weights, list) else list(mesh.weights or [])
        out = []
        for p, primitive in enumerate(mesh.primitives or []):
            pwhere = f"{where}, mesh {node.mesh} primitive {p}"
            if primitive.targets and any(float(w) != 0.0 for w in weights):
                raise self.fail(pwhere, "has morph targets with non-zero weights; apply them (bake the shape) "
                                        "in your modelling tool")
            out.append(self.primitive(primitive, node_name, node.mesh, p, matrix, pwhere))
        return out

    def primitive(self, primitive, node_name: str, mesh_index: int, p: int,  # type: ignore[no-untyped-def]
                  matrix: np.ndarray, where: str) -> MeshPart:
        mode = 4 if primitive.mode is None else primitive.mode
        if mode not in (4, 5, 6):
            raise self.fail(where, f"draws {_MODES.get(mode, f'mode {mode}')}; psyop draws triangles only: "
                                   "convert points and lines to triangle geometry in your modelling tool")
        attributes = primitive.attributes
        if attributes.POSITION is None:
            raise self.fail(where, "has no POSITION attribute; re-export the model")
        positions = self.accessor(attributes.POSITION, where, widths=("VEC3",)).astype(np.float64)
        n = positions.shape[0]
        if not np.all(np.isfinite(positions)):
            bad = int(np.argmax(~np.all(np.isfinite(positions), axis=1)))
            raise self.fail(where, f"vertex {bad} is not finite ({positions[bad].tolist()}); fix the model")
        if primitive.indices is not None:
            raw = self.accessor(primitive.indices, where, widths=("SCALAR",))
            if raw.dtype.kind != "u":
                raise self.fail(where, "indices are not unsigned integers; re-export the model")
            flat = raw[:, 0].astype(np.int64)
        else:
            flat = np.arange(n, dtype=np.int64)
        if flat.size and int(flat.max()) >= n:
            raise self.fail(where, f"index {int(flat.max())} is out of range for its {n} vertices; the file is "
                                   "corrupt, re-export the model")
        triangles = _triangles(flat, mode)
        if triangles is None:
            raise self.fail(where, f"{flat.size} indices do not make whole triangles; re-export the model")
        if triangles.shape[0] > MAX_MESH_TRIANGLES:
            raise self.fail(where, f"has {triangles.shape[0]} triangles, over psyop's {MAX_MESH_TRIANGLES} per "
                                   "model; decimate it")

        normals = texcoords = colours = None
        if attributes.NORMAL is not None:
            normals = self.vertex_attribute(attributes.NORMAL, n, "NORMAL", where, ("VEC3",))
        if attributes.TEXCOORD_0 is not None:
            texcoords = self.vertex_attribute(attributes.TEXCOORD_0, n, "TEXCOORD_0", where, ("VEC2",))
        if attributes.COLOR_0 is not None:
            colours = self.vertex_attribute(attributes.COLOR_0, n, "COLOR_0", where, ("VEC3", "VEC4"))
            if colours.shape[1] == 3:
                colours = np.concatenate([colours, np.ones((n, 1))], axis=1)

        linear = matrix[:3, :3]
        positions = positions @ linear.T + matrix[:3, 3]
        if normals is not None:
            transformed = normals @ np.linalg.inv(linear)  # == (inv(linear).T @ n.T).T, the inverse-transpose
            length = np.linalg.norm(transformed, axis=1, keepdims=True)
            normals = np.divide(transformed, length, out=np.zeros_like(transformed), where=length > 0)
        if np.linalg.det(linear) < 0:  # a mirroring transform flips the winding (glTF 2.0, 3.7.4)
            triangles = triangles[:, [0, 2, 1]]
        base_colour, texture, alpha_mode, cutoff, double_sided = self.material(primitive.material, where)
        return MeshPart(
            node=node_name, mesh_index=int(mesh_index), primitive_index=p, positions=positions,
            indices=np.ascontiguousarray(triangles, dtype=np.uint32),
            normals=None if normals is None else normals.astype(np.float32),
            texcoords=None if texcoords is None else texcoords.astype(np.float32),
            colours=None if colours is None else colours.astype(np.float32),
            base_colour=base_colour, texture=texture, alpha_mode=alpha_mode, alpha_cutoff=cutoff,
            double_sided=double_sided,
            bbox_min=positions.min(axis=0) if n else np.zeros(3), bbox_max=positions.max(axis=0) if n else np.zeros(3))

    def vertex_attribute(self, index: int, n: int, name: str, where: str, widths: tuple[str, ...]) -> np.ndarray:
        values = self.accessor(index, f"{where} {name}", widths=widths).astype(np.float64)
        if values.shape[0] != n:
            raise self.fail(where, f"{name} has {values.shape[0]} entries for {n} vertices; re-export the model")
        if not np.all(np.isfinite(values)):
            raise self.fail(where, f"{name} has non-finite values; fix the model")
        return values

    def used_resources(self) -> tuple[tuple[str, str], ...]:
        """(relative uri, sha256) of the external files the current selection's buffers and images came from."""
        uris = []
        for kind, index in self.used:
            if kind == "buffer":
                uris.append(self.gltf.buffers[index].uri)
            else:
                image = self.gltf.textures[index].source
                uris.append(self.gltf.images[image].uri if image is not None else None)
        relative = {unquote(uri) for uri in uris if isinstance(uri, str) and not uri.startswith("data:")}
        return tuple(sorted((uri, self.resources.read[uri]) for uri in relative if uri in self.resources.read))

    # -- the scene --------------------------------------------------------------------------
    def roots(self) -> list[int]:
        nodes, scenes = self.gltf.nodes or [], self.gltf.scenes or []
        if scenes:
            scene = self.gltf.scene if self.gltf.scene is not None else 0
            chosen = self.item(scenes, scene, "scene", "scene")
            return list(chosen.nodes or [])
        children = {c for node in nodes for c in (node.children or [])}
        return [i for i in range(len(nodes)) if i not in children]

    def walk(self) -> list[tuple[int, str, np.ndarray, tuple[int, ...]]]:
        """Every node of the scene, depth-first in file order: (index, name, world matrix, ancestors)."""
        nodes = self.gltf.nodes or []
        out: list[tuple[int, str, np.ndarray, tuple[int, ...]]] = []
        seen: set[int] = set()
        stack: list[tuple[int, np.ndarray, tuple[int, ...]]] = [(r, np.eye(4), ()) for r in reversed(self.roots())]
        while stack:
            index, parent, ancestors = stack.pop()
            node = self.item(nodes, index, "node", f"node {ancestors[-1] if ancestors else 'scene root'}")
            if index in seen:
                raise self.fail(f"node {index}", "appears twice in the scene's hierarchy (a cycle or a shared "
                                                 "child); glTF nodes form a tree, re-export the model")
            seen.add(index)
            world = parent @ self.local_matrix(index, node)
            out.append((index, node_name(node.name, index), world, ancestors))
            for child in reversed(node.children or []):
                stack.append((child, world, ancestors + (index,)))
        return out

    def local_matrix(self, index: int, node) -> np.ndarray:  # type: ignore[no-untyped-def]
        where = f"node {index} ('{node_name(node.name, index)}')"
        try:
            if node.matrix is not None:
                m = np.asarray(node.matrix, dtype=np.float64)
                if m.shape != (16,):
                    raise ValueError("matrix is not 16 numbers")
                matrix = m.reshape(4, 4).T  # glTF stores column-major
            else:
                matrix = trs_matrix(node.translation, node.rotation, node.scale)
        except (TypeError, ValueError) as error:
            raise self.fail(where, f"transform is not valid ({error}); re-export the model") from None
        if not np.all(np.isfinite(matrix)):
            raise self.fail(where, "transform is not finite; fix the model")
        return matrix


def node_name(name: object, index: int) -> str:
    """A node's name in the file, or ``node<index>`` when it has none."""
    return name if isinstance(name, str) and name else f"node{index}"


def trs_matrix(translation: object, rotation: object, scale: object) -> np.ndarray:
    """glTF's T * R * S (rotation a unit quaternion [x, y, z, w]) as a 4x4 float64 matrix."""
    t = np.asarray(translation if translation is not None else [0, 0, 0], dtype=np.float64)
    q = np.asarray(rotation if rotation is not None else [0, 0, 0, 1], dtype=np.float64)
    s = np.asarray(scale if scale is not None else [1, 1, 1], dtype=np.float64)
    if t.shape != (3,) or q.shape != (4,) or s.shape != (3,):
        raise ValueError("translation, rotation and scale must have 3, 4 and 3 numbers")
    norm = float(np.linalg.norm(q))
    if not norm > 0:
        raise ValueError("rotation quaternion is zero")
    x, y, z, w = q / norm
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    matrix = np.eye(4)
    matrix[:3, :3] = r * s[None, :]
    matrix[:3, 3] = t
    return matrix


def _triangles(flat: np.ndarray, mode: int) -> np.ndarray | None:
    """Triangle-list indices (m, 3) from TRIANGLES, TRIANGLE_STRIP or TRIANGLE_FAN indices; None if ragged."""
    if mode == 4:
        return flat.reshape(-1, 3) if flat.size % 3 == 0 else None
    if flat.size < 3:
        return np.zeros((0, 3), dtype=np.int64)
    k = np.arange(flat.size - 2)
    if mode == 5:  # strip: odd triangles swap their first two vertices to keep the winding
        even = k % 2 == 0
        a = np.where(even, flat[k], flat[k + 1])
        b = np.where(even, flat[k + 1], flat[k])
        return np.stack([a, b, flat[k + 2]], axis=1)
    return np.stack([np.full(k.size, flat[0]), flat[k + 1], flat[k + 2]], axis=1)  # fan


def decode_texture_rgba(data: bytes, where: str) -> np.ndarray:
    """PNG/JPEG bytes as (h, w, 4) float32, top row first, RGB sRGB-decoded to linear, alpha as stored."""
    from PIL import Image

    try:
        with Image.open(io.BytesIO(data)) as image:
            if image.format not in _IMAGE_FORMATS:
                raise UserError(f"{where}: a {image.format} image; glTF textures are PNG or JPEG, convert it")
            if max(image.size) > MAX_TEXTURE_SIDE_PX:
                raise UserError(f"{where}: {image.size[0]} x {image.size[1]} texels, over psyop's "
                                f"{MAX_TEXTURE_SIDE_PX} per side; downscale the texture")
            pixels = np.asarray(image.convert("RGBA"), dtype=np.float32) / 255.0
    except UserError:
        raise
    except Exception as error:  # noqa: BLE001 - Pillow raises many types for a bad file; all are the user's input
        raise UserError(f"{where}: not a readable PNG or JPEG image ({type(error).__name__}: {error}); "
                        "re-export the texture") from None
    pixels[:, :, :3] = srgb_to_linear(pixels[:, :, :3]).astype(np.float32)
    return pixels


def _blend_last(parts: list[MeshPart]) -> tuple[MeshPart, ...]:
    """File order, with every BLEND part moved after all OPAQUE and MASK parts (a stable partition)."""
    return tuple([p for p in parts if p.alpha_mode is not AlphaMode.BLEND]
                 + [p for p in parts if p.alpha_mode is AlphaMode.BLEND])


def _parse(path: Path, raw: bytes) -> _Reader:
    """The one parse of a model file's container and document (its buffers and images are read and decoded
    lazily, once each, by the nodes selected from it)."""
    return _Reader(path, raw)


def _load(path: Path, raw: bytes, node: str | None) -> MeshAsset:
    """Parse ``raw`` and select ``node`` (or the whole scene)."""
    return _select(_parse(path, raw), node)


def _chosen_nodes(reader: _Reader, node: str | None) -> list[tuple[int, str, np.ndarray, tuple[int, ...]]]:
    """The walked nodes under ``node`` (all of the scene when None); an unknown or ambiguous name is refused."""
    walked = reader.walk()
    if node is None:
        return walked
    path = reader.path
    matches = [w for w in walked if w[1] == node]
    if not matches:
        names = [w[1] for w in walked]
        shown = ", ".join(f"'{n}'" for n in names[:30]) + (f" and {len(names) - 30} more" if len(names) > 30 else "")
        raise UserError(f"{path}: no node named '{node}' in the model's scene; its nodes are {shown or 'none'}")
    if len(matches) > 1:
        raise UserError(f"{path}: {len(matches)} nodes are named '{node}' (nodes "
                        f"{', '.join(str(m[0]) for m in matches)}); rename them so the name picks one")
    chosen = matches[0][0]
    return [w for w in walked if w[0] == chosen or chosen in w[3]]


def _select(reader: _Reader, node: str | None) -> MeshAsset:
    """The asset of one node (with its descendants) of a parsed model, or of its whole scene."""
    path = reader.path
    reader.used = set()
    try:
        parts: list[MeshPart] = []
        for index, name, world, _ in _chosen_nodes(reader, node):
            if reader.gltf.nodes[index].mesh is not None:
                parts.extend(reader.parts(index, name, world))
        total = sum(p.triangle_count for p in parts)
        if total > MAX_MESH_TRIANGLES:
            raise UserError(f"{path}: {total} triangles{f' under node {node!r}' if node else ''}, over psyop's "
                            f"{MAX_MESH_TRIANGLES} per model; decimate it")
    except UserError:
        raise
    except (TypeError, ValueError, AttributeError, KeyError, IndexError) as error:
        raise UserError(f"{path}: not a valid glTF 2.0 model ({type(error).__name__}: {error}); "
                        "re-export the model as glTF 2.0") from None
    parts = [p for p in parts if p.triangle_count]
    if not parts:
        what = f"node '{node}'" if node else "the model's scene"
        raise UserError(f"{path}: {what} has no triangles; choose a node with a mesh or re-export the model")
    return MeshAsset(
        path=path, sha256=reader.sha256, node=node, parts=_blend_last(parts),
        bbox_min=np.min([p.bbox_min for p in parts], axis=0), bbox_max=np.max([p.bbox_max for p in parts], axis=0),
        resources=reader.used_resources())


def load_mesh(path: Path, node: str | None = None, *, base_dir: Path) -> MeshAsset:
    """Load a glTF 2.0 model, or one node of its scene (and the node's children), into a :class:`MeshAsset`.

    Parameters
    ----------
    path
        The ``.gltf`` or ``.glb`` file, relative to ``base_dir`` (the protocol's folder) or absolute.
        Buffers and images it names must lie in its own folder or below.
    node
        A node's name in the file's scene; the node keeps its place in the scene (its ancestors'
        transforms are baked in too), so a node picked from a file sits where it does in the whole.
    base_dir
        The folder relative paths start from.

    Returns
    -------
    MeshAsset
        Every mesh primitive under the scene (or the node) with node transforms baked in, BLEND
        parts after the others.

    Raises
    ------
    UserError
        One line naming the file (and node, mesh and primitive) and the fix, for every input psyop
        cannot draw as written.
    """
    full = Path(base_dir) / path
    raw = _model_file(full).read_bytes(full)
    return _load(full, raw, node)


class MeshFiles:
    """The models of one session, each file parsed once and each (file, node) selected once per content.

    ``load`` reads the model file (bounded) and hashes it; an asset is reused when the path, the node and
    the SHA-256 of the model and of every file it read match, so an edited model or texture is loaded again
    and an unchanged one never is (``loads`` counts selections made, ``parses`` the files parsed). Two nodes
    of one file share its parse: the document, its buffers and its decoded textures (one MeshTexture object
    per image, so a renderer uploads it once), as long as the file and every file it read are unchanged.
    One is made per command and passed explicitly to validation (``load_protocol(..., meshes=)``),
    the session.json records and the session's scene, so each model is parsed once in all of them.
    Looking up costs reading and hashing the files, no parsing or decoding: call it once per
    item and session (or per trial where a factor picks the file).
    """

    def __init__(self, base_dir: Path) -> None:
        self.base_dir = Path(base_dir)
        self._assets: dict[tuple[str, str | None], MeshAsset] = {}
        self._readers: dict[str, _Reader] = {}  # resolved path -> its parse (checked against the file's hash)
        self.loads = 0
        self.parses = 0

    def load(self, path: Path | str, node: str | None = None, *, base_dir: Path | None = None) -> MeshAsset:
        """The model at ``path`` (relative to ``base_dir``, default the cache's own folder), or one node of it."""
        full = Path(base_dir if base_dir is not None else self.base_dir) / path
        raw = _model_file(full).read_bytes(full)
        digest = sha256_hex(raw)
        resolved = str(full.resolve())
        key = (resolved, node)
        cached = self._assets.get(key)
        if cached is not None and cached.sha256 == digest and self._resources_unchanged(full, cached.resources):
            return cached
        reader = self._readers.get(resolved)
        if reader is None or reader.sha256 != digest or \
                not self._resources_unchanged(full, tuple(reader.resources.read.items())):
            reader = _parse(full, raw)
            self.parses += 1
            self._readers[resolved] = reader
        asset = _select(reader, node)
        self.loads += 1
        self._assets[key] = asset
        return asset

    @staticmethod
    def _resources_unchanged(model: Path, resources: tuple[tuple[str, str], ...]) -> bool:
        folder = model.parent
        for uri, digest in resources:
            target = folder.joinpath(*PurePosixPath(uri.replace("\\", "/")).parts)
            try:
                reader = InputFile(what=uri, give="a file", max_bytes=MAX_MESH_FILE_BYTES, typical="",
                                   not_found="{path}")
                if sha256_hex(reader.read_bytes(target)) != digest:
                    return False
            except UserError:
                return False
        return True
