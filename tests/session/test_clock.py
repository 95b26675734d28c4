"""Clocks: the virtual clock never sleeps; the real one paces; flip-time regression."""

from __future__ import annotations

import time

import numpy as np
import pytest

from psyop.session.clock import FlipSync, RealClock, VirtualClock


def test_virtual_clock_jumps_without_sleeping(monkeypatch: pytest.MonkeyPatch) -> None:
    def no_sleep(_: float) -> None:
        raise AssertionError("the virtual clock slept")

    monkeypatch.setattr(time, "sleep", no_sleep)  # any real wait fails, however fast the machine
    clock = VirtualClock()
    for k in range(1000):
        clock.sleep_until(k * 10.0)
    assert clock.now_s() == pytest.approx(9990.0)
    clock.sleep_until(5.0)  # never backwards
    assert clock.now_s() == pytest.approx(9990.0)
    with pytest.raises(ValueError):
        clock.advance(-1.0)


def test_real_clock_sleeps_until_the_deadline() -> None:
    """Never early. How late (sleep overshoot) is a duration: benchmarks/bench_session_latency.py."""
    clock = RealClock()
    for dt_s in (0.0, 0.0005, 0.002, 0.02):
        target = clock.now_s() + dt_s
        clock.sleep_until(target)
        assert clock.now_s() >= target
    clock.sleep_until(clock.now_s() - 1.0)  # a past deadline returns at once


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
