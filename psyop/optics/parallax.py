"""Analytic ocular-parallax and acuity models (paper Sec. 3, Fig. 3; supplement Sec. 1).

Geometry: two points straight ahead of the eye's centre of rotation C, at distances z_near and
z_far (metres from C, or diopters 1/z; 0 D = infinity). The eye rotates by e about C, moving
the front nodal point N (the centre of projection, NC in front of C) to
NC (sin e, 0, -cos e). The retinal images of the two points then sit near eccentricity e and
are separated by the angle the two points subtend at N: the relative ocular parallax.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from psyop.optics.eye_models import DEFAULT_EYE_MODEL

#: Guenter et al. (2012) acuity falloff as used by the paper: omega = m e + omega_0 (degrees).
MAR_SLOPE = 0.022
MAR_FOVEA_DEG = 1.0 / 60.0


def _direction_to(points_D: np.ndarray, nodal: np.ndarray) -> np.ndarray:
    """Unit vectors from ``nodal`` (..., 3) to points on the -z axis at ``points_D`` diopters."""
    # Work with the point scaled by its diopters to keep 0 D (infinity) finite:
    # (0, 0, -1/D) - N  is parallel to  (0, 0, -1) - D * N.
    d = points_D[..., None]
    vec = np.array([0.0, 0.0, -1.0]) - d * nodal
    return vec / np.linalg.norm(vec, axis=-1, keepdims=True)


def ocular_parallax_exact_rad(
    eccentricity_deg: ArrayLike, near_D: ArrayLike, far_D: ArrayLike, nc_m: float = DEFAULT_EYE_MODEL.nc_m
) -> np.ndarray:
    """Exact angle (rad) between two on-axis points at ``near_D`` and ``far_D`` seen from the
    nodal point of an eye rotated by ``eccentricity_deg``. Broadcasts over its inputs."""
    e = np.deg2rad(np.asarray(eccentricity_deg, dtype=np.float64))
    near = np.asarray(near_D, dtype=np.float64)
    far = np.asarray(far_D, dtype=np.float64)
    e, near, far = np.broadcast_arrays(e, near, far)
    nodal = nc_m * np.stack([np.sin(e), np.zeros_like(e), -np.cos(e)], axis=-1)
    a = _direction_to(near, nodal)
    b = _direction_to(far, nodal)
    # atan2(|a x b|, a.b) is accurate for tiny angles, unlike arccos.
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))


def ocular_parallax_small_angle_rad(
    eccentricity_deg: ArrayLike, near_D: ArrayLike, far_D: ArrayLike, nc_m: float = DEFAULT_EYE_MODEL.nc_m
) -> np.ndarray:
    """First-order approximation: NC sin(e) |near_D - far_D| (rad), linear in diopters."""
    e = np.deg2rad(np.asarray(eccentricity_deg, dtype=np.float64))
    return nc_m * np.sin(e) * np.abs(np.asarray(near_D, dtype=np.float64) - np.asarray(far_D, dtype=np.float64))


def bingham_parallax_rad(
    back_m: ArrayLike, front_m: ArrayLike, rotation_deg: float = 15.0, nc_m: float = DEFAULT_EYE_MODEL.nc_m
) -> np.ndarray:
    """Parallax at an occluding edge after an eye rotation (supplement, after Bingham 1993).

    The front edge (``front_m`` from C) and a back-surface point (``back_m``, may be inf) are
    aligned with the nodal point while looking straight ahead. After a rotation about C by
    ``rotation_deg`` the nodal point sits at (NC sin a, -NC cos a) in the x-z plane, and the
    visual directions of the two points differ by

        atan2(NC sin a, z_front - NC cos a) - atan2(NC sin a, z_back - NC cos a).

    The supplement gives no formula; this is the closed form of that geometry (it equals
    :func:`ocular_parallax_exact_rad`, which is tested). Returns radians.
    """
    a = np.deg2rad(float(rotation_deg))
    back = np.asarray(back_m, dtype=np.float64)
    front = np.asarray(front_m, dtype=np.float64)
    lateral = nc_m * np.sin(a)
    axial = nc_m * np.cos(a)
    return np.arctan2(lateral, front - axial) - np.arctan2(lateral, back - axial)


def bingham_parallax_diopters_rad(
    back_D: ArrayLike, separation_D: ArrayLike, rotation_deg: float = 15.0, nc_m: float = DEFAULT_EYE_MODEL.nc_m
) -> np.ndarray:
    """:func:`bingham_parallax_rad` with the back surface at ``back_D`` and the front surface
    ``separation_D`` diopters nearer (front at back_D + separation_D)."""
    back_D = np.asarray(back_D, dtype=np.float64)
    front_D = back_D + np.asarray(separation_D, dtype=np.float64)
    with np.errstate(divide="ignore"):
        back_m = np.where(back_D == 0, np.inf, 1.0 / np.where(back_D == 0, 1.0, back_D))
    return bingham_parallax_rad(back_m, 1.0 / front_D, rotation_deg, nc_m)


def minimum_angle_of_resolution_deg(
    eccentricity_deg: ArrayLike, slope: float = MAR_SLOPE, fovea_deg: float = MAR_FOVEA_DEG
) -> np.ndarray:
    """Guenter et al. (2012): omega = 0.022 e + 1/60 degrees."""
    return slope * np.asarray(eccentricity_deg, dtype=np.float64) + fovea_deg


def retinal_speed_deg_s(eccentricity_deg: ArrayLike, angular_speed_deg_s: ArrayLike) -> np.ndarray:
    """Retinal speed of a target circling the view centre at eccentricity e with angular speed
    w, as the paper computes it: sin(e) * w (16 deg, 90 deg/s -> 24.81 deg/s)."""
    return np.sin(np.deg2rad(np.asarray(eccentricity_deg, dtype=np.float64))) * np.asarray(
        angular_speed_deg_s, dtype=np.float64
    )
