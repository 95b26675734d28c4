"""Clocks: the virtual clock never sleeps; the real one paces; flip-time regression."""

from __future__ import annotations

import time

import numpy as np
import pytest

from psyop.session.clock import FlipSync, RealClock, VirtualClock


def test_virtual_clock_jumps_without_sleeping() -> None:
    clock = VirtualClock()
    start = time.perf_counter()
    for k in range(1000):
        clock.sleep_until(k * 10.0)
    assert clock.now_s() == pytest.approx(9990.0)
    assert time.perf_counter() - start < 0.5
    clock.sleep_until(5.0)  # never backwards
    assert clock.now_s() == pytest.approx(9990.0)
    with pytest.raises(ValueError):
        clock.advance(-1.0)


def test_real_clock_sleeps_until_the_deadline() -> None:
    clock = RealClock()
    target = clock.now_s() + 0.02
    clock.sleep_until(target)
    assert 0 <= clock.now_s() - target < 0.005


def test_flip_sync_estimates_period_and_next_flip_from_noisy_flips() -> None:
    rng = np.random.default_rng(0)
    period = 1 / 89.53
    flips = FlipSync()
    for k in range(200):
        flips.add(0.3 + k * period + rng.normal(0, 2e-4))
    est_period, phase = flips.estimate(1 / 90)
    assert est_period == pytest.approx(period, rel=1e-4)
    next_flip = flips.next_flip_s(0.3 + 200.4 * period, 1 / 90)
    assert next_flip == pytest.approx(0.3 + 201 * period, abs=5e-4)
