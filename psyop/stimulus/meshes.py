"""Mesh scene items (``kind: mesh``) -> placed :class:`psyop.rendering.mesh_scene.MeshInstance`.

:class:`SessionMeshes` loads each (file, node) once per session (psyop.mesh.MeshFiles) and hands the
same :class:`psyop.mesh.MeshAsset` object to every frame, so the renderer uploads it once.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from psyop.errors import UserError
from psyop.mesh.asset import MeshAsset
from psyop.protocol import scene as ps
from psyop.protocol.mesh_models import protocol_models
from psyop.protocol.model import Protocol
from psyop.rendering.builders import direction_from_angles, place_centre_m
from psyop.rendering.mesh_scene import MeshInstance, model_matrix
from psyop.stimulus.placement import centre_angles_deg
from psyop.records import JsonMapping

if TYPE_CHECKING:
    from psyop.mesh.load import MeshFiles


class SessionMeshes:
    """The session's models by the protocol's (file, node), looked up without touching the files
    again (a scene is built every frame); each is loaded once through :class:`psyop.mesh.MeshFiles`."""

    def __init__(self, base_dir: Path | None, files: MeshFiles | None = None) -> None:
        from psyop.mesh.load import MeshFiles

        self.base_dir = base_dir or Path.cwd()
        self._files = files if files is not None else MeshFiles(self.base_dir)  # the command's, when given
        self._assets: dict[tuple[str, str | None], MeshAsset] = {}

    def asset(self, file: str, node: str | None) -> MeshAsset:
        key = (file, node)
        if key not in self._assets:
            self._assets[key] = self._files.load(file, node, base_dir=self.base_dir)
        return self._assets[key]

    def records(self) -> list[dict[str, object]]:
        """What session.json records of every model read (MeshAsset.record)."""
        return [asset.record() for asset in self._assets.values()]


def protocol_mesh_records(protocol: Protocol, base_dir: Path | None,
                          mesh_files: MeshFiles | None = None) -> list[dict[str, object]]:
    """session.json's ``meshes``: the record (MeshAsset.record) of every (file, node) the protocol's mesh
    items can show (every level of a factor on ``file`` or ``node``; psyop.protocol.mesh_models), read when
    the session opens, whether or not the session renders images.
    ``mesh_files``: the session's model cache (the models validation read are not read again)."""
    files = SessionMeshes(base_dir, mesh_files)
    for file, node in protocol_models(protocol):
        files.asset(file, node)
    return files.records()


def _number(value: float | ps.FactorRef | None) -> float:
    """A mesh's number field once resolve_factor_fields has put the trial's level in it."""
    assert value is not None and not isinstance(value, ps.FactorRef)  # resolved; None ruled out by the caller
    return float(value)


def _direction3(direction: Sequence[float]) -> tuple[float, float, float]:
    """A light direction (3 numbers, checked by the protocol) as a tuple of Python floats."""
    x, y, z = (float(v) for v in direction)
    return x, y, z


def mesh_instance(item: ps.Mesh, values: JsonMapping, origin_m: np.ndarray, files: SessionMeshes) -> MeshInstance:
    """The placed model of a mesh item whose factor fields hold this trial's numbers; a factor on ``file`` or
    ``node`` picks the trial's model (each loaded once per session by ``files``)."""
    try:
        file, node = item.model_for(values)
    except ValueError as error:
        raise UserError(f"scene item '{item.id}': {error}") from None
    asset = files.asset(file, node)
    extent = asset.largest_extent
    rotation = tuple(_number(a) for a in item.rotation_deg)
    if item.position_m is not None:
        position = np.array([_number(v) for v in item.position_m])
        pivot = np.zeros(3)
        distance = float(np.linalg.norm(position - origin_m))
    else:
        assert item.depth is not None
        depth_D = item.depth.resolve_D(values)
        if not (math.isfinite(depth_D) and depth_D > 0):
            raise UserError(f"scene item '{item.id}': a mesh needs a finite depth, got {depth_D} D")
        distance = 1.0 / depth_D
        az, el = centre_angles_deg(item.centre_deg if item.centre_deg is not None else (0.0, 0.0))
        position = place_centre_m(direction_from_angles(az, el), distance, origin_m, facing="eye")
        pivot = (np.asarray(asset.bbox_min, dtype=np.float64) + np.asarray(asset.bbox_max, dtype=np.float64)) / 2.0
    if item.scale is not None:
        scale = _number(item.scale)
    elif item.size_m is not None or item.size_deg is not None:
        if not extent > 0:
            raise UserError(f"scene item '{item.id}': the model has no extent to size (a flat point set)")
        size_m = _number(item.size_m) if item.size_m is not None else \
            2.0 * distance * math.tan(math.radians(_number(item.size_deg)) / 2.0)
        scale = size_m / extent
    else:
        scale = 1.0
    model = model_matrix(position, rotation, scale, pivot)
    if item.light is not None:
        return MeshInstance(asset, tuple(model.reshape(-1).tolist()), item.id, item.shading,
                            _direction3(item.light.direction), float(item.light.ambient))
    return MeshInstance(asset, tuple(model.reshape(-1).tolist()), item.id, item.shading)


def reach_mesh_instance(name: str, obj: ps.ReachMesh, values: JsonMapping, centre_m: tuple[float, float, float],
                        size_m: float, files: SessionMeshes) -> MeshInstance:
    """A reach target's model (psyop.protocol.scene.ReachMesh): its bounding box's centre at ``centre_m`` (head
    space: where the analytic target's centre would be), its largest extent ``size_m``, turned about that centre."""
    try:
        file, node = obj.model_for(values)
    except ValueError as error:
        raise UserError(f"scene item '{name}': {error}") from None
    asset = files.asset(file, node)
    if not asset.largest_extent > 0:
        raise UserError(f"scene item '{name}': the model has no extent to size (a flat point set)")
    pivot = (np.asarray(asset.bbox_min, dtype=np.float64) + np.asarray(asset.bbox_max, dtype=np.float64)) / 2.0
    rotation = tuple(float(a) for a in obj.rotation_deg)
    model = model_matrix(np.asarray(centre_m, dtype=np.float64), rotation, size_m / asset.largest_extent, pivot)
    return MeshInstance(asset, tuple(model.reshape(-1).tolist()), name, "unlit")
