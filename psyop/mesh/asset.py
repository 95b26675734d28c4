"""The typed contract between loading a glTF 2.0 model and drawing it.

A :class:`MeshAsset` is what :func:`psyop.mesh.load_mesh` returns and what the rasterising pass
(``psyop.rendering``) and the audit's ray-triangle check consume. It is plain numpy data,
prepared once per session and apart from any GL call (moderngl's model: data first, then
explicit GL resources built from it).

Coordinates: glTF 2.0 is right-handed, metres, +Y up, and an asset's front faces +Z. psyop's
head/world space is right-handed, metres, x right, y up, -z forward (docs/architecture.md), so
the axes map one to one (identity): a model placed in front of the viewer shows its front.
Every node transform of the file's scene is baked into the vertices at load time, so
``positions`` are in the model's root frame (model units, normally metres); an item's placement
(position, rotation, scale) is applied later as one model matrix.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from pathlib import Path

import numpy as np


class AlphaMode(str, Enum):
    """glTF ``material.alphaMode``."""

    OPAQUE = "OPAQUE"
    MASK = "MASK"  # a fragment is kept where alpha >= alpha_cutoff, else discarded
    BLEND = "BLEND"


class Wrap(str, Enum):
    """glTF sampler wrap modes (10497, 33071, 33648)."""

    REPEAT = "repeat"
    CLAMP = "clamp"
    MIRROR = "mirror"


class Filter(str, Enum):
    """Texture filters: glTF's 9728 nearest, 9729 linear; mipmapped minification is ``LINEAR_MIPMAP``."""

    NEAREST = "nearest"
    LINEAR = "linear"
    LINEAR_MIPMAP = "linear_mipmap"


@dataclass(frozen=True, eq=False)
class MeshTexture:
    """A base-colour texture, decoded once.

    ``rgba_linear``: (height, width, 4) float32, top row first, colour channels sRGB-decoded to
    linear light (glTF stores base colour in sRGB), alpha as stored. ``key`` identifies the
    content (file SHA-256 and image index) so a renderer can keep one upload per content.
    """

    key: str
    rgba_linear: np.ndarray
    wrap_s: Wrap = Wrap.REPEAT
    wrap_t: Wrap = Wrap.REPEAT
    mag_filter: Filter = Filter.LINEAR
    min_filter: Filter = Filter.LINEAR_MIPMAP


@dataclass(frozen=True, eq=False)
class MeshPart:
    """One glTF mesh primitive under one node: a triangle list with one material.

    Arrays (n vertices, m triangles):
    - ``positions``: (n, 3) float64, model root frame (node transforms baked in).
    - ``normals``: (n, 3) float32 unit vectors in the same frame, or None (flat shading from
      the triangle's winding where a shading model needs one).
    - ``texcoords``: (n, 2) float32 glTF TEXCOORD_0 (u right, v down from the image's top row), or None.
    - ``colours``: (n, 4) float32 linear COLOR_0 (RGB expanded to alpha 1), or None.
    - ``indices``: (m, 3) uint32 (non-indexed files get 0..n-1).
    Material: ``base_colour`` (4,) linear RGBA factor, ``texture`` or None, ``alpha_mode``,
    ``alpha_cutoff`` (MASK only), ``double_sided``.
    ``node`` is the node's name (or ``node<i>`` when it has none); ``mesh_index`` and
    ``primitive_index`` locate it in the file for error messages.
    ``bbox_min``/``bbox_max``: (3,) float64 bounds of ``positions`` (culling per part).
    """

    node: str
    mesh_index: int
    primitive_index: int
    positions: np.ndarray
    indices: np.ndarray
    normals: np.ndarray | None
    texcoords: np.ndarray | None
    colours: np.ndarray | None
    base_colour: tuple[float, float, float, float]
    texture: MeshTexture | None
    alpha_mode: AlphaMode
    alpha_cutoff: float
    double_sided: bool
    bbox_min: np.ndarray
    bbox_max: np.ndarray

    @property
    def triangle_count(self) -> int:
        return int(self.indices.shape[0])


@dataclass(frozen=True, eq=False)
class MeshAsset:
    """A loaded glTF 2.0 file (or one node of its scene), ready to upload.

    ``parts`` are drawn in order; BLEND parts come after all opaque and mask parts (the loader
    orders them and docs/rendering.md states the rule). ``sha256`` is the file's (a ``.gltf``'s
    own bytes, its ``.bin`` and images hashed in ``resources``).
    """

    path: Path
    sha256: str
    node: str | None
    parts: tuple[MeshPart, ...]
    bbox_min: np.ndarray
    bbox_max: np.ndarray
    resources: tuple[tuple[str, str], ...] = ()  # (relative uri, sha256) of each external file read

    @property
    def triangle_count(self) -> int:
        return sum(p.triangle_count for p in self.parts)

    @property
    def largest_extent(self) -> float:
        """The bounding box's largest side in model units (``size_m``/``size_deg`` scale this)."""
        return float(np.max(self.bbox_max - self.bbox_min))

    def record(self) -> dict[str, object]:
        """What session.json records of this model: file name, SHA-256, triangles, bounding box."""
        return {
            "file": self.path.name,
            "node": self.node,
            "sha256": self.sha256,
            "resources": [{"uri": uri, "sha256": digest} for uri, digest in self.resources],
            "triangle_count": self.triangle_count,
            "bbox_min": [float(v) for v in self.bbox_min],
            "bbox_max": [float(v) for v in self.bbox_max],
        }
