"""psyop.optics.rotation is the one quaternion implementation, and it gives the results the four
copies it replaced gave (rendering/transform.py, optics/camera.py, devices/xr/runtime.py,
session/pose.py; issue 28), bit for bit."""

from __future__ import annotations

import hashlib
import math

import numpy as np
from scipy.spatial.transform import Rotation

from psyop.optics import rotation

# sha256 of the outputs of the former copies (rendering.transform.rotation_matrix; xr.runtime's rotate
# and quaternion_multiply) at commit 6ac037f, on the inputs of _inputs() below; ViewGeometry.rotation's
# former copy gave the same matrices bit for bit
BEFORE_MATRICES_SHA256 = "b107519e8833080f925f19a6433ea4df3e51757ad8adec15b2a372e0241a39db"
BEFORE_ROTATE_MULTIPLY_SHA256 = "6586f7ef7fac2bc1a8004c863cdb77845da536ddf77346d2b47bdf440cf29fd0"


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


def _sha256(rows: list) -> str:
    return hashlib.sha256(np.ascontiguousarray(np.array(rows, dtype=np.float64)).tobytes()).hexdigest()


def test_same_bits_as_the_former_copies() -> None:
    matrices, others = [], []
    for q, q2, v in _inputs():
        matrices.append(rotation.rotation_matrix(q).ravel())
        others.append((*rotation.rotate(q, v), *rotation.quaternion_multiply(q, q2)))
    assert _sha256(matrices) == BEFORE_MATRICES_SHA256
    assert _sha256(others) == BEFORE_ROTATE_MULTIPLY_SHA256


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
