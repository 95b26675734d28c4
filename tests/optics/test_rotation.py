"""psyop.optics.rotation is the one quaternion implementation, and it gives the results the four
copies it replaced gave (rendering/transform.py, optics/camera.py, devices/xr/runtime.py,
session/pose.py; issue 28): the former copies are kept below and run beside it on the same machine."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from psyop.optics import rotation

pytestmark = pytest.mark.cross_cpu


def _former_rotation_matrix(orientation_wxyz: Sequence[float]) -> np.ndarray:
    """rendering.transform.rotation_matrix at 6ac037f (ViewGeometry.rotation's copy gave the same matrices)."""
    w, x, y, z = np.asarray(orientation_wxyz, dtype=np.float64) / np.linalg.norm(orientation_wxyz)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def _former_quaternion_multiply(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float, float]:
    """devices/xr/runtime.py's quaternion_multiply at 6ac037f."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def _former_rotate(q: tuple[float, ...], v: tuple[float, float, float]) -> tuple[float, float, float]:
    """devices/xr/runtime.py's rotate at 6ac037f."""
    w, x, y, z = q
    p = _former_quaternion_multiply(_former_quaternion_multiply((w, x, y, z), (0.0, *v)), (w, -x, -y, -z))
    return (p[1], p[2], p[3])


def _inputs(n: int = 2000):
    rng = np.random.default_rng(28)
    for i in range(n):
        q = rng.normal(size=4)
        if i % 2:
            q = q / np.linalg.norm(q)
        q = tuple(float(v) for v in q)
        q2 = tuple(float(v) for v in rng.normal(size=4))
        v = tuple(float(c) for c in rng.normal(size=3))
        rng.uniform(-3.2, 3.2, size=3)  # the yaw, pitch and roll the reference drew
        yield q, q2, v


#: the matrices' tolerance (absolute; every entry lies in [-1, 1]): the former copy normalised with
#: np.linalg.norm, whose dot product (BLAS) rounds by the CPU's kernel; one ulp of the norm moves an entry by
#: at most a few ulp of 1 (2.2e-16 each), and 8 ulp of 1 bounds that
MATRIX_ATOL = 8 * np.finfo(float).eps


def test_same_results_as_the_former_copies() -> None:
    """Products and rotations are plain float arithmetic in the same order as before: equal bit for bit on any
    IEEE-754 machine (no libm, no BLAS). Matrices to MATRIX_ATOL, the former copy's own rounding."""
    worst = 0.0
    for q, q2, v in _inputs():
        worst = max(worst, float(np.max(np.abs(rotation.rotation_matrix(q) - _former_rotation_matrix(q)))))
        assert rotation.rotate(q, v) == _former_rotate(q, v)
        assert rotation.quaternion_multiply(q, q2) == _former_quaternion_multiply(q, q2)
    assert worst <= MATRIX_ATOL, worst


def test_the_matrix_check_can_fail() -> None:
    """A matrix one rounding step of 1e-14 away is caught by the tolerance."""
    q = (0.3, -0.5, 0.2, 0.7)
    assert np.max(np.abs(rotation.rotation_matrix(q) - _former_rotation_matrix((0.3 + 1e-14, -0.5, 0.2, 0.7)))) > MATRIX_ATOL


def test_one_implementation_everywhere() -> None:
    from psyop.devices.xr import runtime
    from psyop.rendering import transform
    from psyop.session import pose

    assert transform.rotation_matrix is rotation.rotation_matrix
    assert transform.IDENTITY_WXYZ is rotation.IDENTITY_WXYZ
    assert runtime.rotate is rotation.rotate and runtime.quaternion_multiply is rotation.quaternion_multiply
    assert pose.quaternion_from_yaw_pitch_roll is rotation.quaternion_from_yaw_pitch_roll


def test_agrees_with_scipy() -> None:
    for q, _, v in _inputs(200):
        expected = Rotation.from_quat(q, scalar_first=True)
        np.testing.assert_allclose(rotation.rotation_matrix(q), expected.as_matrix(), atol=1e-12)
        unit = tuple(c / math.sqrt(sum(x * x for x in q)) for c in q)
        np.testing.assert_allclose(rotation.rotate(unit, v), expected.apply(v), atol=1e-12)
    yaw, pitch, roll = 0.3, -0.2, 0.1
    q = rotation.quaternion_from_yaw_pitch_roll(yaw, pitch, roll)
    expected = Rotation.from_euler("YXZ", (yaw, pitch, roll)).as_quat(scalar_first=True)
    np.testing.assert_allclose(q, expected * np.sign(expected[0]) * np.sign(q[0]), atol=1e-12)
