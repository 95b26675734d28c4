"""Rigid transforms of a scene: a world-fixed scene seen from a moving head.

Scenes are built in the head space of the session's start ("world"). A tracked head pose
(position ``t`` in metres and unit quaternion ``q`` = (w, x, y, z), head -> world) moves the
eyes through that world; rendering needs the scene in the current head space:
``p_head = R(q)^T (p_world - t)``, with the half axes rotated alike. The aperture is
display-fixed and is left alone. A primitive at optical infinity is a direction: it rotates with
the head but no translation moves it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from psyop.optics.rotation import IDENTITY_WXYZ as IDENTITY_WXYZ, rotation_matrix as rotation_matrix
from psyop.rendering.scene import Scene


def rotate_rows(r: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """``r @ v`` for each row ``v`` of ``vectors`` ((n, 3) -> (n, 3)), as three elementwise products and
    two sums in a fixed order.

    Not a BLAS product: ``vectors @ r.T`` (gemm) and ``r @ v`` (gemv) may round differently on another CPU
    (FMA, other blocking), and the vectorised and per-primitive motions must agree bit for bit everywhere.
    """
    return vectors[:, 0:1] * r[:, 0] + vectors[:, 1:2] * r[:, 1] + vectors[:, 2:3] * r[:, 2]


def scene_in_head(scene: Scene, head_position_m: Sequence[float], head_orientation_wxyz: Sequence[float]) -> Scene:
    """``scene`` (world coordinates) expressed in the head space of the given head pose.

    The identity pose returns ``scene`` itself, so a still head keeps frame reuse and
    uploads nothing new. Runs every frame of a head-tracked session, so every primitive is moved in
    one numpy product (the same numbers as the per-primitive form in benchmarks/former.py, bit for bit:
    tests/rendering/test_renderer_cache_equality.py).

    Examples
    --------
    >>> from psyop.rendering.builders import frontoparallel_disc
    >>> from psyop.rendering.scene import Solid
    >>> scene = Scene((frontoparallel_disc(1.0, 2.0, Solid((1, 0, 0))),))
    >>> scene_in_head(scene, (0.0, 0.0, 0.5), IDENTITY_WXYZ).primitives[0].centre_m
    (0.0, 0.0, -1.5)
    """
    t = np.asarray(head_position_m, dtype=np.float64)
    if not np.any(t) and tuple(float(c) for c in head_orientation_wxyz) == IDENTITY_WXYZ:
        return scene
    if not scene.primitives:
        return dataclasses.replace(scene, primitives=(), meshes=_moved_meshes(scene, t, head_orientation_wxyz))
    r_t = rotation_matrix(head_orientation_wxyz).T
    prims = scene.primitives
    shift = np.array([(0.0, 0.0, 0.0) if p.at_infinity else t for p in prims], dtype=np.float64)
    centres = rotate_rows(r_t, np.array([p.centre_m for p in prims]) - shift).tolist()
    half_u = rotate_rows(r_t, np.array([p.half_u_m for p in prims])).tolist()
    half_v = rotate_rows(r_t, np.array([p.half_v_m for p in prims])).tolist()
    moved = tuple(p.moved(tuple(c), tuple(u), tuple(v)) for p, c, u, v in zip(prims, centres, half_u, half_v, strict=True))
    if scene.meshes:
        return dataclasses.replace(scene, primitives=moved, meshes=_moved_meshes(scene, t, head_orientation_wxyz))
    return dataclasses.replace(scene, primitives=moved)


def _moved_meshes(scene: Scene, head_position_m: np.ndarray, head_orientation_wxyz: Sequence[float]) -> tuple:
    """The scene's mesh instances in the head space of the pose: ``p_head = R^T (M p - t)`` folded into each
    model matrix (float64), lights rotated alike."""
    if not scene.meshes:
        return ()
    r_t = rotation_matrix(head_orientation_wxyz).T
    head_from_world = np.eye(4)
    head_from_world[:3, :3] = r_t
    head_from_world[:3, 3] = -(r_t @ np.asarray(head_position_m, dtype=np.float64))
    return tuple(m.moved(head_from_world, r_t) for m in scene.meshes)
