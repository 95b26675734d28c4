"""A simulated binocular eye tracker: plausible gaze with the real tracker's faults.

Stateless in time: the sample at tick k is a pure function of (seed, k, the active
plan), so the same session seed gives the same gaze whether or not a session was
interrupted, and a virtual clock may jump over seconds without generating the samples
in between.

Model (defaults from the paper and its supplement):
- 120 Hz, 10 ms latency (a sample of time t is available at t + latency).
- Pursuit of a moving target with gain < 1, modelled as a phase lag of
  ``(1 - gain) * pursuit_time_constant_s``; fixational noise 0.08 deg sd (precision).
- Free viewing: fixations of gamma-distributed duration (mean 0.3 s) at random points of
  the aperture, joined by 30 ms saccades.
- Tracker error: a random offset per fixation plan (phase) whose size is such that,
  after a single-point recalibration, the mean residual error at the centre is
  ``error_centre_deg``; plus a per-session error growing by ``error_per_15deg`` at 15 deg
  eccentricity. The supplement measured 1.18 deg on average over the centre and four
  targets at 15 deg after recalibration, lowest at the centre, at most 1.6 deg.
- Drift: a per-session offset that grows ``drift_deg_per_min``; the per-trial
  recalibration removes it.
- Blinks (Poisson, 150 ms), NaN bursts and dropouts (no samples at all) on request.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass

import numpy as np

from psyop.session.gaze.plan import FixationPlan
from psyop.optics.angles import fick_angles_deg, offset_direction
from psyop.session.gaze.sample import GazeSample, RawBuffer, RawGazeSample, angles_to_direction
from psyop.session.gaze.sync import ClockSync


@dataclass(frozen=True)
class SimulatedTrackerConfig:
    rate_hz: float = 120.0
    latency_s: float = 0.010
    precision_deg: float = 0.08
    pursuit_gain: float = 0.9
    pursuit_time_constant_s: float = 0.2
    error_centre_deg: float = 0.9
    error_per_15deg: float = 0.8
    drift_start_deg: float = 0.5
    drift_deg_per_min: float = 0.3
    blink_rate_hz: float = 0.25
    blink_s: float = 0.15
    nan_burst_rate_hz: float = 0.0
    nan_burst_s: float = 0.05
    dropout_rate_hz: float = 0.0
    dropout_s: float = 0.5
    fixation_mean_s: float = 0.3
    saccade_s: float = 0.03


def _rng(*keys: int) -> np.random.Generator:
    return np.random.default_rng([k & 0xFFFFFFFF for k in keys])


class _EventTimes:
    """Poisson events (blinks, NaN bursts, dropouts), drawn per 1 s window and cached."""

    def __init__(self, seed: int, stream: int, rate_hz: float, duration_s: float) -> None:
        self.seed, self.stream, self.rate_hz, self.duration_s = seed, stream, rate_hz, duration_s
        self._cache: dict[int, list[float]] = {}

    def _starts(self, window: int) -> list[float]:
        """The window's event starts, ascending (Python floats: a sample looks through a few of them)."""
        starts = self._cache.get(window)
        if starts is None:
            if len(self._cache) > 64:
                self._cache.clear()
            rng = _rng(self.seed, self.stream, window)
            starts = (window + np.sort(rng.uniform(0, 1, rng.poisson(self.rate_hz)))).tolist()
            self._cache[window] = starts
        return starts

    def start_containing(self, t_s: float) -> float | None:
        """Start time of the earliest event covering ``t_s``, or None."""
        if self.rate_hz <= 0:
            return None
        for w in range(int(math.floor(t_s - self.duration_s)), int(math.floor(t_s)) + 1):
            for start in self._starts(w):
                if start > t_s:
                    break  # ascending: no later one has begun
                if t_s < start + self.duration_s:
                    return start
        return None


class SimulatedTracker:
    """Implements :class:`~psyop.session.gaze.sample.GazeSource` from a fixation plan."""

    def __init__(self, seed: int, config: SimulatedTrackerConfig | None = None) -> None:
        self.config = c = config or SimulatedTrackerConfig()
        self.seed = int(seed) & 0xFFFFFFFF
        rng = _rng(self.seed, 1)
        self._error_dir = _unit2(rng)
        self._error_grow_dir = _unit2(rng)
        self._drift_dir = _unit2(rng)
        self._plans: list[FixationPlan] = [FixationPlan("cross", 0.0)]
        self._fixations: tuple[tuple[int, float], list[tuple[float, float, float]]] | None = None
        self._delivered = 0
        self._noise_cache: tuple[int, np.ndarray] | None = None
        self._offset_cache: tuple[tuple[int, int], np.ndarray] | None = None  # the current plan's error offset
        self._dropouts = _EventTimes(self.seed, 3, c.dropout_rate_hz, c.dropout_s)
        self._blinks = _EventTimes(self.seed, 4, c.blink_rate_hz, c.blink_s)
        self._nan_bursts = _EventTimes(self.seed, 5, c.nan_burst_rate_hz, c.nan_burst_s)
        self._raw = RawBuffer()
        self._last_raw_tick = -1

    # GazeSource --------------------------------------------------------------------
    def start(self) -> None:
        return None

    def close(self) -> None:
        return None

    def stats(self) -> dict[str, float | int]:
        return {"samples_delivered": self._delivered, "gaps": 0}

    def clock_sync(self) -> ClockSync | None:
        """None: simulated samples are stamped on the session clock."""
        return None

    def drain_raw(self) -> list[RawGazeSample]:
        """Each tick a :meth:`latest` call delivered, once (the simulation is stateless in time, so
        it delivers the ticks it is asked for, not a 120 Hz stream behind a jumping virtual clock)."""
        return self._raw.drain()

    def set_plan(self, plan: FixationPlan) -> None:
        """Gaze follows ``plan`` from ``plan.start_s`` on (plans must come in time order)."""
        self._plans = [p for p in self._plans if p.start_s < plan.start_s][-1:] + [plan]

    def latest(self, now_s: float) -> GazeSample | None:
        c = self.config
        k = math.floor((now_s - c.latency_s) * c.rate_hz)
        for _ in range(8):  # a dropout delivers nothing: step back to the tick before it
            if k < 0:
                return None
            start = self._dropouts.start_containing(k / c.rate_hz)
            if start is None:
                break
            k = math.ceil(start * c.rate_hz) - 1
        if k < 0:
            return None
        self._delivered += 1
        sample = self.sample_at(k / c.rate_hz, k)
        if k > self._last_raw_tick:
            self._last_raw_tick = k
            self._raw.add(RawGazeSample.of(sample, received_s=sample.timestamp_s + c.latency_s))
        return sample

    # model -------------------------------------------------------------------------
    def sample_at(self, t_s: float, tick: int) -> GazeSample:
        c = self.config
        if self._blinks.start_containing(t_s) is not None or self._nan_bursts.start_containing(t_s) is not None:
            return GazeSample(t_s, (math.nan, math.nan, math.nan), 0.0, False)
        plan = self._plan_at(t_s)
        az, el = self._eye_angles(plan, t_s)
        noise = self._noise(tick)
        ecc = math.hypot(az, el)
        err = self._plan_offset(plan) + self._error_grow_dir * c.error_per_15deg * (ecc / 15.0)
        drift = self._drift_dir * (c.drift_start_deg + c.drift_deg_per_min * t_s / 60.0)
        f = angles_to_direction(az + noise[0] + err[0] + drift[0], el + noise[1] + err[1] + drift[1]) * plan.distance_m
        confidence = float(np.clip(0.95 + 0.02 * noise[2] / c.precision_deg, 0.0, 1.0))
        return GazeSample(t_s, (float(f[0]), float(f[1]), float(f[2])), confidence, True)

    def _plan_offset(self, plan: FixationPlan) -> np.ndarray:
        """Per-plan error offset; the difference of two has mean norm ``error_centre_deg``. Drawn once per
        plan (its key), not per sample: the same numbers, without a numpy Generator per sample."""
        key = (int(round(plan.start_s * 1000.0)), plan.seed)
        if self._offset_cache is None or self._offset_cache[0] != key:
            self._offset_cache = (key, self._draw_plan_offset(*key))
        return self._offset_cache[1]

    def _draw_plan_offset(self, start_ms: int, plan_seed: int) -> np.ndarray:
        sigma = self.config.error_centre_deg / (math.sqrt(2.0) * math.sqrt(math.pi / 2.0))
        offset = _rng(self.seed, 8, start_ms, plan_seed).normal(0.0, sigma, 2)
        offset.setflags(write=False)  # shared by every sample of the plan
        return offset

    def _noise(self, tick: int) -> np.ndarray:
        """Three normal draws for ``tick`` (two angles scaled to the precision, one spare)."""
        window, index = divmod(tick, 256)
        if self._noise_cache is None or self._noise_cache[0] != window:
            table = _rng(self.seed, 6, window).normal(0.0, self.config.precision_deg, (256, 3))
            self._noise_cache = (window, table)
        return self._noise_cache[1][index]

    def true_direction(self, t_s: float) -> np.ndarray:
        """Where the simulated eye really points (no tracker error): for tests."""
        return angles_to_direction(*self._eye_angles(self._plan_at(t_s), t_s))

    def _plan_at(self, t_s: float) -> FixationPlan:
        active = self._plans[0]
        for plan in self._plans:
            if plan.start_s <= t_s:
                active = plan
        return active

    def _eye_angles(self, plan: FixationPlan, t_s: float) -> tuple[float, float]:
        c = self.config
        if plan.kind == "pursuit" and plan.target is not None:
            lag = (1.0 - c.pursuit_gain) * c.pursuit_time_constant_s
            return plan.target(max(0.0, t_s - plan.start_s - lag))
        if plan.kind == "free":
            return self._free_viewing(plan, t_s - plan.start_s)
        return plan.centre_deg

    def _free_viewing(self, plan: FixationPlan, t_rel_s: float) -> tuple[float, float]:
        c = self.config
        key = (plan.seed, plan.start_s)
        if self._fixations is None or self._fixations[0] != key or self._fixations[1][-1][0] < t_rel_s:
            rng = _rng(self.seed, 7, plan.seed)
            fixations, t = [], 0.0
            while t <= max(t_rel_s, 10.0):
                r = plan.radius_deg * math.sqrt(rng.uniform())
                a = rng.uniform(0, 2 * math.pi)
                # r deg from the centre at polar angle a (docs/optics.md, "Angles"), as Fick angles
                az, el = fick_angles_deg(offset_direction(*plan.centre_deg, r, math.degrees(a)))
                fixations.append((t, float(az), float(el)))
                t += rng.gamma(4.0, c.fixation_mean_s / 4.0)
            self._fixations = (key, fixations)
        fixations = self._fixations[1]
        index = max(i for i, f in enumerate(fixations) if f[0] <= max(t_rel_s, 0.0))
        start, az, el = fixations[index]
        if index > 0 and t_rel_s - start < c.saccade_s:
            _, paz, pel = fixations[index - 1]
            w = (t_rel_s - start) / c.saccade_s
            return paz + w * (az - paz), pel + w * (el - pel)
        return az, el


def _unit2(rng: np.random.Generator) -> np.ndarray:
    a = rng.uniform(0, 2 * math.pi)
    return np.array([math.cos(a), math.sin(a)])


def angular_error_deg(measured: np.ndarray, truth: np.ndarray) -> float:
    """Angle between two head-space directions, degrees."""
    cosang = float(np.dot(measured, truth) / (np.linalg.norm(measured) * np.linalg.norm(truth)))
    return math.degrees(math.acos(min(1.0, max(-1.0, cosang))))


def seed_for(*parts: object) -> int:
    """A stable 32-bit seed from strings/ints (Python's hash() is salted per process)."""
    return zlib.crc32("|".join(str(p) for p in parts).encode())
