"""Mesh items of a rendering scene: a loaded glTF model (:class:`psyop.mesh.MeshAsset`) placed by one model matrix.

A :class:`MeshInstance` is what a :class:`psyop.rendering.scene.Scene` holds for each ``kind: mesh``
scene item: the asset (loaded once per session, shared by every frame), a float64 4x4 model matrix
(model root frame -> head space, metres) and how it is shaded. The rasterising pass
(:mod:`psyop.rendering.mesh_pass`) and the exact ray-triangle path (:mod:`psyop.rendering.mesh_exact`)
read only these fields.

Shading (docs/rendering.md, "Meshes"): ``unlit`` draws base colour x vertex colour x texture (linear
light, the default: known luminances); ``lambert`` multiplies that albedo by
``ambient + (1 - ambient) * max(0, n . l)`` with ``light_direction`` the unit vector towards a distant
white light in head space.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from psyop.mesh.asset import MeshAsset

Shading = Literal["unlit", "lambert"]


@dataclass(frozen=True)
class MeshInstance:
    """One placed mesh: ``asset`` drawn with ``model_m`` (16 floats, row-major 4x4, model -> head space).

    ``name`` is the scene item's id (``psyop audit`` maps pixels back to items by it). Equality compares the
    asset by identity (one object per loaded file and node) and the numbers by value, so a scene built
    again from the same session assets equals the last one (frame reuse keeps working).
    """

    asset: MeshAsset
    model_m: tuple[float, ...]
    name: str = ""
    shading: Shading = "unlit"
    light_direction: tuple[float, float, float] = (0.0, 1.0, 0.0)
    ambient: float = 1.0

    def __post_init__(self) -> None:
        model = tuple(float(v) for v in np.asarray(self.model_m, dtype=np.float64).reshape(-1))
        if len(model) != 16 or not all(math.isfinite(v) for v in model):
            raise ValueError(f"mesh {self.name!r}: model_m must be 16 finite numbers")
        object.__setattr__(self, "model_m", model)
        if self.shading not in ("unlit", "lambert"):
            raise ValueError(f"mesh {self.name!r}: shading must be unlit or lambert, got {self.shading!r}")
        light = np.asarray(self.light_direction, dtype=np.float64).reshape(3)
        norm = float(np.linalg.norm(light))
        if not (math.isfinite(norm) and norm > 0):
            raise ValueError(f"mesh {self.name!r}: light_direction must be a non-zero 3-vector")
        object.__setattr__(self, "light_direction", tuple(float(v) for v in light / norm))
        if not 0.0 <= float(self.ambient) <= 1.0:
            raise ValueError(f"mesh {self.name!r}: ambient must lie in [0, 1]")

    @property
    def model(self) -> np.ndarray:
        """The model matrix as a float64 (4, 4) array."""
        return np.array(self.model_m, dtype=np.float64).reshape(4, 4)

    def moved(self, head_from_world: np.ndarray, rotation: np.ndarray) -> MeshInstance:
        """This instance seen from a moved head: ``head_from_world`` (4x4) applied after the model matrix and
        the light rotated by ``rotation`` (3x3, the same motion's rotation)."""
        model = head_from_world @ self.model
        light = rotation @ np.asarray(self.light_direction, dtype=np.float64)
        return MeshInstance(self.asset, tuple(model.reshape(-1).tolist()), self.name, self.shading,
                            tuple(light.tolist()), self.ambient)

    def bounding_sphere_m(self) -> tuple[np.ndarray, float]:
        """Centre (head space) and radius of a sphere around the placed bounding box (reuse bounds, far clip)."""
        lo, hi = np.asarray(self.asset.bbox_min, dtype=np.float64), np.asarray(self.asset.bbox_max, dtype=np.float64)
        model = self.model
        centre = model[:3, :3] @ ((lo + hi) / 2.0) + model[:3, 3]
        radius = float(np.linalg.norm(model[:3, :3], ord=2) * np.linalg.norm(hi - lo) / 2.0)
        return centre, radius


def rotation_yaw_pitch_roll(rotation_deg: Sequence[float]) -> np.ndarray:
    """3x3 rotation of ``[yaw, pitch, roll]`` degrees: yaw about +y (counter-clockwise seen from above: a model
    facing the viewer, front +z, turns its front to the viewer's right), then pitch about +x (positive tips its front up),
    then roll about +z (positive turns it counter-clockwise as the viewer sees it); R = Ry Rx Rz.

    Examples
    --------
    >>> r = rotation_yaw_pitch_roll([90.0, 0.0, 0.0])
    >>> [round(float(v), 12) for v in r @ [0.0, 0.0, 1.0]]  # the front (+z) now faces +x
    [1.0, 0.0, 0.0]
    """
    yaw, pitch, roll = (math.radians(float(a)) for a in rotation_deg)
    cy, sy, cp, sp, cr, sr = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch), math.cos(roll), math.sin(roll)
    ry = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]])
    rz = np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]])
    return ry @ rx @ rz


def model_matrix(position_m: ArrayLike, rotation_deg: Sequence[float], scale: float,
                 pivot_m: ArrayLike = (0.0, 0.0, 0.0)) -> np.ndarray:
    """4x4 float64 model matrix: the model point ``pivot_m`` (model units) lands at ``position_m`` (head space),
    the model scaled by ``scale`` (model units -> metres) and rotated by :func:`rotation_yaw_pitch_roll`
    about that point: ``p_head = position + R (scale (p - pivot))``."""
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"scale must be a positive number, got {scale}")
    r = rotation_yaw_pitch_roll(rotation_deg) * float(scale)
    m = np.eye(4)
    m[:3, :3] = r
    m[:3, 3] = np.asarray(position_m, dtype=np.float64) - r @ np.asarray(pivot_m, dtype=np.float64)
    return m
