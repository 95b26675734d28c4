"""CirclingTarget.positions (psyop.session.gaze.plan) computes the target's Fick angles one direction
component at a time: held bit for bit to its definition, fick_angles_deg(offset_direction_in(frame, polar)),
for random circles (centres off the straight-ahead, eccentricities up to 80 deg, both directions, large
phases), random times (scalar, empty, thousands), and to calling the target one time at a time (to round-off)."""

from __future__ import annotations

import numpy as np
import pytest

from psyop.optics.angles import fick_angles_deg, offset_direction_in
from psyop.session.gaze.plan import circling_target

pytestmark = pytest.mark.cross_cpu  # fast per-component positions against their definition, bit for bit


def _by_definition(target, t_rel_s) -> np.ndarray:
    polar = target.phase_deg + target.speed_deg_s * np.asarray(t_rel_s, dtype=np.float64)
    az, el = fick_angles_deg(offset_direction_in(target._frame, polar))
    return np.stack([np.asarray(az, dtype=np.float64).reshape(-1), np.asarray(el, dtype=np.float64).reshape(-1)],
                    axis=-1)


def test_positions_equal_their_definition_bit_for_bit():
    rng = np.random.default_rng(20261203)
    for _ in range(400):
        target = circling_target(float(rng.uniform(0.0, 80.0)), float(rng.uniform(-720.0, 720.0)),
                                 float(rng.uniform(-1e4, 1e4)), (float(rng.uniform(-60, 60)), float(rng.uniform(-60, 60))))
        for t in (rng.uniform(0.0, 10.0, int(rng.integers(1, 4000))), np.array([]), 0.37, np.arange(0, 513) * 0.0005):
            got, want = target.positions(t), _by_definition(target, t)
            assert got.shape == want.shape
            assert got.tobytes() == want.tobytes()


def test_positions_agree_with_the_target_called_per_time():
    target = circling_target(16.0, -90.0, 33.0, (2.0, -3.0))
    t = np.linspace(0.0, 4.0, 97)
    per_time = np.array([target(float(x)) for x in t])
    assert np.allclose(target.positions(t), per_time, rtol=0, atol=1e-9)
