"""Session clocks: a real monotonic clock and a virtual clock that never sleeps.

Both expose seconds as float64 since the clock's own epoch. The loop only ever asks
``now_s`` and ``sleep_until``; with :class:`VirtualClock` a whole session runs as fast
as the CPU allows and is reproducible, with :class:`RealClock` it runs in real time.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np


class Clock(Protocol):
    """What the trial loop needs from a clock."""

    virtual: bool

    def now_s(self) -> float: ...

    def sleep_until(self, t_s: float) -> None: ...


class RealClock:
    """Monotonic wall clock (``perf_counter_ns``; on Linux that is ``CLOCK_MONOTONIC``, the clock an
    OpenXR runtime converts its times from: psyop.devices.xr)."""

    virtual = False

    def __init__(self) -> None:
        self._epoch_ns = time.perf_counter_ns()

    @property
    def epoch_ns(self) -> int:
        """The session clock's zero as a ``perf_counter_ns`` reading."""
        return self._epoch_ns

    def now_s(self) -> float:
        return (time.perf_counter_ns() - self._epoch_ns) * 1e-9

    def sleep_until(self, t_s: float) -> None:
        """Sleep coarsely, then spin the last 0.5 ms (sleep overshoots by ~0.1-1 ms)."""
        while True:
            remaining = t_s - self.now_s()
            if remaining <= 0:
                return
            if remaining > 0.0015:
                time.sleep(remaining - 0.001)


class VirtualClock:
    """A clock that advances only when told to: ``sleep_until`` jumps, never waits."""

    virtual = True

    def __init__(self, start_s: float = 0.0) -> None:
        self._t_s = float(start_s)

    def now_s(self) -> float:
        return self._t_s

    def sleep_until(self, t_s: float) -> None:
        self._t_s = max(self._t_s, float(t_s))

    def advance(self, dt_s: float) -> None:
        if dt_s < 0:
            raise ValueError("a clock cannot go backwards")
        self._t_s += float(dt_s)


@dataclass
class FlipSync:
    """Estimates the display's refresh period and phase from flip timestamps.

    A least-squares line through (flip index, time) gives period and phase; this turns
    noisy flip times into a predicted next-flip time for scheduling frames.
    """

    capacity: int = 240
    times_s: list[float] = field(default_factory=list)

    def add(self, t_s: float) -> None:
        self.times_s.append(t_s)
        if len(self.times_s) > self.capacity:
            del self.times_s[0]

    def estimate(self, nominal_period_s: float) -> tuple[float, float]:
        """(period_s, phase_s) of the flips; the nominal period until there are 8 flips."""
        if len(self.times_s) < 8:
            return nominal_period_s, (self.times_s[-1] if self.times_s else 0.0)
        t = np.asarray(self.times_s, dtype=np.float64)
        # number flips by successive gaps (a missed flip is a gap of ~2 periods), so a small
        # error in the nominal period cannot accumulate into a wrong index
        steps = np.maximum(1.0, np.rint(np.diff(t) / nominal_period_s))
        index = np.concatenate([[0.0], np.cumsum(steps)])
        slope, intercept = np.polyfit(index, t, 1)
        return float(slope), float(intercept)

    def next_flip_s(self, now_s: float, nominal_period_s: float) -> float:
        period, phase = self.estimate(nominal_period_s)
        k = np.floor((now_s - phase) / period) + 1
        return float(phase + k * period)
