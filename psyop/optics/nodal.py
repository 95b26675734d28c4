"""Eye centres, nodal points and centres of projection (paper eq. 1), vectorised.

Head space: right-handed, x right, y up, -z forward, metres, origin midway between the eye
centres of rotation C_L = (-ipd/2, 0, 0) and C_R = (+ipd/2, 0, 0).

Paper eq. 1: F_eye = F - C_eye and N = NC * F_eye / |F_eye| (N relative to C). The centre of
projection is C (conventional), C + N (ocular) or C + (-Nx, -Ny, Nz) (reversed).

A fixation is either a point in head space, shape (..., 3), or a homogeneous 4-vector
(x, y, z, w): w != 0 is the point (x, y, z) / w, w == 0 is a direction at infinity (the same
gaze direction for both eyes). Use :func:`fixation_at_infinity` to build one.

Degenerate fixations never raise and never produce NaN: a fixation that is not finite, lies
within ``min_fixation_distance_m`` of the eye centre, or is not in front of it (rotation from
straight ahead >= ``max_rotation_deg``) is replaced by ``fallback_direction`` (the caller
passes the last valid gaze direction; default straight ahead, (0, 0, -1)) and flagged
``valid = False``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np
from numpy.typing import ArrayLike

STRAIGHT_AHEAD = np.array([0.0, 0.0, -1.0])
#: Fixations closer than this to the eye centre are treated as unusable (tracker glitches).
DEFAULT_MIN_FIXATION_DISTANCE_M = 0.01
#: Fixations rotated this far or further from straight ahead (incl. behind) are unusable.
DEFAULT_MAX_ROTATION_DEG = 90.0


class Eye(str, Enum):
    """Which eye; str-valued so ``Eye.LEFT == "left"``."""

    LEFT = "left"
    RIGHT = "right"

    def __str__(self) -> str:
        return self.value


class RenderingMode(str, Enum):
    """Where the centre of projection sits: C, C + N, or C + (-Nx, -Ny, Nz)."""

    CONVENTIONAL = "conventional"
    OCULAR = "ocular"
    REVERSED = "reversed"

    def __str__(self) -> str:
        return self.value


def parse_eye(eye: Eye | str) -> Eye:
    try:
        return Eye(eye)
    except ValueError:
        raise ValueError(f"eye must be one of {[e.value for e in Eye]}, got {eye!r}") from None


def parse_mode(mode: RenderingMode | str) -> RenderingMode:
    try:
        return RenderingMode(mode)
    except ValueError:
        raise ValueError(f"rendering mode must be one of {[m.value for m in RenderingMode]}, got {mode!r}") from None


def eye_centre_x_m(eye: Eye | str, ipd_m: float) -> float:
    """The x of ``eye``'s centre of rotation in head space: -ipd/2 (left), +ipd/2 (right); the one place
    psyop derives the eye centres from the ipd (rig, camera, validation, export, render)."""
    return (-0.5 if parse_eye(eye) is Eye.LEFT else 0.5) * float(ipd_m)


def eye_centre_m(eye: Eye | str, ipd_m: float) -> np.ndarray:
    """Centre of rotation of ``eye`` in head space: (-/+ ipd/2, 0, 0)."""
    return np.array([eye_centre_x_m(eye, ipd_m), 0.0, 0.0])


def fixation_at_infinity(direction: ArrayLike) -> np.ndarray:
    """A fixation at optical infinity in ``direction`` (homogeneous, w = 0)."""
    d = np.asarray(direction, dtype=np.float64)
    return np.concatenate([d, np.zeros(d.shape[:-1] + (1,))], axis=-1)


@dataclass(frozen=True)
class GazeResult:
    """Per-eye gaze for n fixations: unit ``direction`` (n, 3) from C, ``nodal_offset_m``
    N relative to C (n, 3), and ``valid`` (n,) False where the fallback was used."""

    direction: np.ndarray
    nodal_offset_m: np.ndarray
    valid: np.ndarray


def _unit_fallback(fallback_direction: ArrayLike | None, n: int, min_cos: float) -> np.ndarray:
    if fallback_direction is None:
        return np.broadcast_to(STRAIGHT_AHEAD, (n, 3)).copy()
    fb = np.broadcast_to(np.asarray(fallback_direction, dtype=np.float64), (n, 3))
    with np.errstate(invalid="ignore", over="ignore"):
        norm = np.linalg.norm(fb, axis=-1, keepdims=True)
        unit = fb / np.where(norm > 0, norm, 1.0)
    ok = np.isfinite(unit).all(axis=-1) & (norm[:, 0] > 0) & (-unit[:, 2] > min_cos)
    return np.where(ok[:, None], unit, STRAIGHT_AHEAD)


def gaze_from_fixation(
    fixation: ArrayLike,
    eye_centre: ArrayLike,
    nc_m: float,
    fallback_direction: ArrayLike | None = None,
    min_fixation_distance_m: float = DEFAULT_MIN_FIXATION_DISTANCE_M,
    max_rotation_deg: float = DEFAULT_MAX_ROTATION_DEG,
) -> GazeResult:
    """Paper eq. 1 for n fixations (n, 3) points or (n, 4) homogeneous, one or n eye centres.

    Returns a :class:`GazeResult` (always finite). See the module docstring for the
    definition of a degenerate fixation and the fallback.
    """
    fix = np.atleast_2d(np.asarray(fixation, dtype=np.float64))
    if fix.shape[-1] not in (3, 4):
        raise ValueError(f"fixation must have 3 (point) or 4 (homogeneous) components, got shape {fix.shape}")
    n = fix.shape[0]
    centre = np.broadcast_to(np.asarray(eye_centre, dtype=np.float64), (n, 3))
    min_cos = math.cos(math.radians(max_rotation_deg))
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        if fix.shape[-1] == 4:
            w = fix[:, 3:4]
            at_infinity = (w == 0.0)[:, 0]
            point = fix[:, :3] / np.where(w == 0.0, 1.0, w)
            vec = np.where(at_infinity[:, None], fix[:, :3], point - centre)
            min_dist = np.where(at_infinity, 0.0, min_fixation_distance_m)
        else:
            vec = fix - centre
            min_dist = np.full(n, min_fixation_distance_m)
        norm = np.linalg.norm(vec, axis=-1)
        unit = vec / np.where(norm > 0, norm, 1.0)[:, None]
        valid = (
            np.isfinite(vec).all(axis=-1)
            & np.isfinite(norm)
            & (norm > 0.0)
            & (norm >= min_dist)
            & np.isfinite(unit).all(axis=-1)
            & (-unit[:, 2] > min_cos)
        )
    fallback = _unit_fallback(fallback_direction, n, min_cos)
    direction = np.where(valid[:, None], unit, fallback)
    return GazeResult(direction=direction, nodal_offset_m=float(nc_m) * direction, valid=valid)


def projection_offset_m(nodal_offset_m: ArrayLike, mode: RenderingMode | str) -> np.ndarray:
    """Centre of projection relative to C: 0, N, or (-Nx, -Ny, Nz) by rendering mode."""
    n_off = np.asarray(nodal_offset_m, dtype=np.float64)
    m = parse_mode(mode)
    if m is RenderingMode.CONVENTIONAL:
        return np.zeros_like(n_off)
    if m is RenderingMode.OCULAR:
        return n_off.copy()
    return n_off * np.array([-1.0, -1.0, 1.0])


def paper_eye_matrix(eye: Eye | str, ipd_m: float, nodal_offset_m: ArrayLike) -> np.ndarray:
    """Paper eq. 2-3: E = T(-N) . T(+-ipd/2), view space -> eye space (4x4, float64).

    The second factor translates by +ipd/2 for the left eye and -ipd/2 for the right eye,
    moving that eye's centre of rotation to the origin; T(-N) then moves the nodal point there.
    """
    sign = 1.0 if parse_eye(eye) is Eye.LEFT else -1.0
    t_ipd = np.eye(4)
    t_ipd[0, 3] = sign * 0.5 * float(ipd_m)
    t_n = np.eye(4)
    t_n[:3, 3] = -np.asarray(nodal_offset_m, dtype=np.float64)
    return t_n @ t_ipd


def _unit_or_none(x: float, y: float, z: float, min_norm: float, min_cos: float) -> tuple[float, float, float] | None:
    """(x, y, z) normalised if finite, at least ``min_norm`` long and in front; else None."""
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        return None
    norm = math.sqrt(x * x + y * y + z * z)
    if not (math.isfinite(norm) and norm > 0.0 and norm >= min_norm):
        return None
    ux, uy, uz = x / norm, y / norm, z / norm
    if not -uz > min_cos:
        return None
    return ux, uy, uz


def gaze_direction_single(
    fixation: ArrayLike,
    eye_centre_x_m: float,
    fallback_direction: ArrayLike | None = None,
    min_fixation_distance_m: float = DEFAULT_MIN_FIXATION_DISTANCE_M,
    max_rotation_deg: float = DEFAULT_MAX_ROTATION_DEG,
) -> tuple[tuple[float, float, float], bool]:
    """One fixation's unit gaze direction from the eye centre (-/+ ipd/2, 0, 0) and its validity.

    The scalar twin of :func:`gaze_from_fixation` for the per-frame path (plain floats, no
    array overhead); the tests check that both agree. Never raises for a bad fixation value.
    """
    f = [float(v) for v in np.asarray(fixation, dtype=np.float64).reshape(-1)]
    min_cos = math.cos(math.radians(max_rotation_deg))
    unit = None
    if len(f) == 4 and f[3] == 0.0:
        unit = _unit_or_none(f[0], f[1], f[2], 0.0, min_cos)
    elif len(f) in (3, 4):
        w = f[3] if len(f) == 4 else 1.0
        px, py, pz = f[0] / w, f[1] / w, f[2] / w  # w != 0 here; NaN/inf propagate to "invalid"
        unit = _unit_or_none(px - eye_centre_x_m, py, pz, min_fixation_distance_m, min_cos)
    else:
        raise ValueError(f"fixation must have 3 (point) or 4 (homogeneous) components, got {len(f)}")
    if unit is not None:
        return unit, True
    if fallback_direction is not None:
        fb = [float(v) for v in np.asarray(fallback_direction, dtype=np.float64).reshape(-1)]
        if len(fb) == 3:
            fb_unit = _unit_or_none(fb[0], fb[1], fb[2], 0.0, min_cos)
            if fb_unit is not None:
                return fb_unit, False
    return (0.0, 0.0, -1.0), False
