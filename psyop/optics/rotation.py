"""Rotations as unit quaternions (w, x, y, z): the one implementation the package uses.

Convention: a quaternion ``q`` = (w, x, y, z), scalar first, is the active rotation of a frame
into its parent (eye -> head, head -> world): ``rotate(q, v)`` and ``rotation_matrix(q) @ v``
are the vector ``v`` of the frame expressed in the parent. Hamilton product, right-handed axes
(x right, y up, z back; OpenXR's and psyop's head space).

Every function is plain float arithmetic in a fixed order (no BLAS call), so its results are the
same bit for bit on every CPU.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

IDENTITY_WXYZ = (1.0, 0.0, 0.0, 0.0)


def rotation_matrix(orientation_wxyz: Sequence[float]) -> np.ndarray:
    """3x3 rotation matrix of a quaternion (w, x, y, z), normalised first.

    Parameters
    ----------
    orientation_wxyz
        The quaternion, scalar first; any non-zero norm.

    Returns
    -------
    numpy.ndarray
        (3, 3) float64; its columns are the frame's x, y, z axes in the parent frame.

    Examples
    --------
    A quarter turn about y (up) takes straight ahead (-z) to the left (-x):

    >>> quarter_turn_y = (math.cos(math.pi / 4), 0.0, math.sin(math.pi / 4), 0.0)
    >>> bool(np.allclose(rotation_matrix(quarter_turn_y) @ (0.0, 0.0, -1.0), (-1.0, 0.0, 0.0), atol=1e-15))
    True
    """
    w, x, y, z = (float(v) for v in orientation_wxyz)
    n = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def quaternion_multiply(a: Sequence[float], b: Sequence[float]) -> tuple[float, float, float, float]:
    """Hamilton product ``a b`` of two (w, x, y, z) quaternions (``b`` applied first).

    Examples
    --------
    >>> quaternion_multiply((0.0, 1.0, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0))
    (0.0, 0.0, 0.0, 1.0)
    """
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def rotate(q: Sequence[float], v: Sequence[float]) -> tuple[float, float, float]:
    """The vector ``v`` rotated by the unit quaternion ``q`` (w, x, y, z): ``q (0, v) q*``.

    ``q`` is not normalised (a located OpenXR pose is unit within float32).

    Examples
    --------
    >>> [round(c, 12) + 0.0 for c in rotate((math.cos(math.pi / 4), 0.0, math.sin(math.pi / 4), 0.0), (0.0, 0.0, -1.0))]
    [-1.0, 0.0, 0.0]
    """
    w, x, y, z = q
    p = quaternion_multiply(quaternion_multiply((w, x, y, z), (0.0, *v)), (w, -x, -y, -z))
    return (p[1], p[2], p[3])


def quaternion_from_yaw_pitch_roll(yaw_rad: float, pitch_rad: float, roll_rad: float) -> tuple[float, float, float, float]:
    """Unit quaternion (w, x, y, z) of R_y(yaw) R_x(pitch) R_z(roll) (scipy's intrinsic 'YXZ').

    Examples
    --------
    >>> quaternion_from_yaw_pitch_roll(0.0, 0.0, 0.0)
    (1.0, 0.0, 0.0, 0.0)
    """
    cy, sy = math.cos(yaw_rad / 2), math.sin(yaw_rad / 2)
    cp, sp = math.cos(pitch_rad / 2), math.sin(pitch_rad / 2)
    cr, sr = math.cos(roll_rad / 2), math.sin(roll_rad / 2)
    # q = q_yaw(y) * q_pitch(x) * q_roll(z)
    w = cy * cp * cr + sy * sp * sr
    x = cy * sp * cr + sy * cp * sr
    y = sy * cp * cr - cy * sp * sr
    z = cy * cp * sr - sy * sp * cr
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    return (w / norm, x / norm, y / norm, z / norm)
