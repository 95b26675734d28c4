"""A simulated binocular eye tracker: plausible gaze with the real tracker's faults.

Stateless in time: the sample at tick k is a pure function of (seed, k, the active
plan), so the same session seed gives the same gaze whether or not a session was
interrupted, and a virtual clock may jump over seconds without generating the samples
in between.

Model (defaults from the paper and its supplement):
- 120 Hz, 10 ms latency (a sample of time t is available at t + latency).
- Pursuit of a moving target (:mod:`psyop.session.gaze.pursuit`): smooth pursuit at ``pursuit_gain``
  times the target's velocity, ``pursuit_lag_s`` late, with catch-up saccades on the main sequence
  whenever the eye falls ``catch_up_threshold_deg`` behind; fixational noise 0.08 deg sd (precision).
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

The raw stream (:meth:`SimulatedTracker.drain_raw`): ``raw_stream="requested"`` holds each tick a
:meth:`~SimulatedTracker.latest` call delivered (a headless session on a virtual clock asks for a few
per trial); ``"every_sample"`` holds every tick at ``rate_hz`` from the first call on, as a real
tracker delivers them (computed in blocks, :meth:`SimulatedTracker.samples_block`; a tick's values
agree with :meth:`~SimulatedTracker.sample_at` to round-off).
"""

from __future__ import annotations

import dataclasses
import math
import zlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from collections.abc import Callable

from psyop.session.gaze.keyed import KeyedGenerator, keyed_poisson_uniforms, keyed_rng
from psyop.session.gaze.plan import CirclingTarget, FixationPlan
from psyop.session.gaze.pursuit import CatchUp, CatchUpStream, PursuitParams, eye_positions
from psyop.optics.angles import fick_angles_deg, fick_direction, offset_direction
from psyop.session.gaze.sample import GazeSample, RawBuffer, RawGazeSample, angles_to_direction
from psyop.session.gaze.sync import ClockSync

if TYPE_CHECKING:
    from psyop.protocol.simulated_eye import SimulatedEye


@dataclass(frozen=True)
class SimulatedTrackerConfig:
    rate_hz: float = 120.0
    latency_s: float = 0.010
    precision_deg: float = 0.08
    pursuit_gain: float = 0.9
    pursuit_lag_s: float = 0.02
    catch_up_threshold_deg: float = 1.5
    main_sequence_vmax_deg_s: float = 500.0
    main_sequence_c_deg: float = 8.0
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
    #: requested | every_sample (module docstring); None: the protocol's observer: eye: decides (else requested).
    #: Set here (psyop power: requested) it wins over the protocol.
    raw_stream: str | None = None


@dataclass(frozen=True)
class SampleBlock:
    """Many ticks' samples (:meth:`SimulatedTracker.samples_block`): times (s), fixation points (n, 3),
    confidence, valid (not in a blink or NaN burst) and delivered (not in a dropout)."""

    t_s: np.ndarray
    fixation_m: np.ndarray
    confidence: np.ndarray
    valid: np.ndarray
    delivered: np.ndarray


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
            # rng.uniform(0, 1, rng.poisson(rate)) of the window's stream, sorted (stepped in Python integers:
            # the same numbers, without a Generator per window); no event (most windows): the empty list
            starts = [window + u for u in sorted(keyed_poisson_uniforms(self.rate_hz, self.seed, self.stream, window))]
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

    def covers(self, t_s: np.ndarray) -> np.ndarray:
        """Whether an event covers each of ``t_s`` (ascending), at once: ``start <= t < start + duration_s``
        of an event begun in a window the times reach, each event's times found by bisection."""
        t_s = np.asarray(t_s, dtype=np.float64)
        if self.rate_hz <= 0 or not len(t_s):
            return np.zeros(len(t_s), dtype=bool)
        starts = [start for w in range(int(math.floor(t_s[0] - self.duration_s)), int(math.floor(t_s[-1])) + 1)
                  for start in self._starts(w)]
        if np.any(np.diff(t_s) < 0):  # not ascending: event by event over every time
            covered = np.zeros(len(t_s), dtype=bool)
            for start in starts:
                covered |= (t_s >= start) & (t_s < start + self.duration_s)
            return covered
        first = np.searchsorted(t_s, starts, side="left")  # each event's times: [first, stop)
        stop = np.searchsorted(t_s, [start + self.duration_s for start in starts], side="left")
        some = stop > first
        depth = np.zeros(len(t_s) + 1, dtype=np.int64)
        np.add.at(depth, first[some], 1)
        np.add.at(depth, stop[some], -1)
        return np.cumsum(depth[:-1]) > 0


class SimulatedTracker:
    """Implements :class:`~psyop.session.gaze.sample.GazeSource` from a fixation plan."""

    def __init__(self, seed: int, config: SimulatedTrackerConfig | None = None) -> None:
        self.config = c = config or SimulatedTrackerConfig()
        self.seed = int(seed) & 0xFFFFFFFF
        rng = keyed_rng(self.seed, 1)
        self._error_dir = _unit2(rng)
        self._error_grow_dir = _unit2(rng)
        self._drift_dir = _unit2(rng)
        self._plans: list[FixationPlan] = [FixationPlan("cross", 0.0)]
        self._fixations: tuple[tuple[int, float], list[tuple[float, float, float]]] | None = None
        self._delivered = 0
        self._noise_cache: tuple[int, np.ndarray] | None = None
        self._offset_cache: tuple[tuple[int, int], np.ndarray] | None = None  # the current plan's error offset
        self._offset_floats: tuple[tuple[int, int], tuple[float, float]] | None = None  # the same, as floats
        # sample_at's noise: the window and the rows drawn so far from its stream in _noise_generator (_noise_row)
        self._noise_rows: tuple[int, np.ndarray] | None = None
        # generators re-seeded in place (psyop.session.gaze.keyed): the noise rows' (drawn on as a window is read)
        # and a scratch one for the streams drawn at once (plan offsets, noise tables, free-viewing fixations)
        self._noise_generator, self._scratch = KeyedGenerator(), KeyedGenerator()
        self._error_grow = (float(self._error_grow_dir[0]), float(self._error_grow_dir[1]))
        self._drift = (float(self._drift_dir[0]), float(self._drift_dir[1]))
        self._dropouts = _EventTimes(self.seed, 3, c.dropout_rate_hz, c.dropout_s)
        self._blinks = _EventTimes(self.seed, 4, c.blink_rate_hz, c.blink_s)
        self._nan_bursts = _EventTimes(self.seed, 5, c.nan_burst_rate_hz, c.nan_burst_s)
        self._raw = RawBuffer()
        self._last_raw_tick = -1
        self._stream_next: int | None = None  # every_sample: the next tick to stream (None: not started)
        self._catch_up_cache: tuple[tuple[int, int, int], CatchUpStream] | None = None
        if c.raw_stream not in (None, "requested", "every_sample"):
            raise ValueError(f"raw_stream must be requested or every_sample, not {c.raw_stream!r}")

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
        if self.config.raw_stream == "every_sample":  # the ticks before it, under the plans they belong to
            self._stream_until(math.ceil(plan.start_s * self.config.rate_hz) - 1)
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
        if c.raw_stream == "every_sample":
            self._stream_until(k)
        elif k > self._last_raw_tick:
            self._last_raw_tick = k
            self._raw.add(RawGazeSample.of(sample, received_s=sample.timestamp_s + c.latency_s))
        return sample

    def _stream_until(self, last_tick: int) -> None:
        """every_sample: add the ticks after the last one streamed up to ``last_tick`` to the raw stream
        (the first call starts the stream at ``last_tick``: a resumed session does not replay the past)."""
        if self._stream_next is None:
            self._stream_next = max(0, last_tick)
        first = self._stream_next
        if last_tick < first:
            return
        self._stream_next = last_tick + 1
        ticks = np.arange(first, last_tick + 1)
        block = self.samples_block(ticks)
        latency = self.config.latency_s
        for i in np.flatnonzero(block.delivered):
            t = float(block.t_s[i])
            fixation = (float(block.fixation_m[i, 0]), float(block.fixation_m[i, 1]), float(block.fixation_m[i, 2]))
            self._raw.add(RawGazeSample(t, t, t + latency, bool(block.valid[i]), float(block.confidence[i]), fixation))

    def samples_block(self, ticks: np.ndarray) -> SampleBlock:
        """The samples of ``ticks`` (ascending) at once: what :meth:`sample_at` gives per tick (to
        round-off), and which ticks a dropout keeps from being delivered. Uses the plans set so far."""
        ticks = np.asarray(ticks, dtype=np.int64)
        starts = np.array([p.start_s for p in self._plans])
        which = np.clip(np.searchsorted(starts, ticks / self.config.rate_hz, side="right") - 1, 0, len(self._plans) - 1)
        return self.samples_under(ticks, self._plans, which)

    def samples_under(self, ticks: np.ndarray, plans: list[FixationPlan], which: np.ndarray) -> SampleBlock:
        """:meth:`samples_block` of ``ticks`` (ascending), tick i under ``plans[which[i]]`` (the plan
        :meth:`set_plan` made active for it), whatever plans are set: a whole stream's ticks at once."""
        c = self.config
        ticks = np.asarray(ticks, dtype=np.int64)
        t = ticks / c.rate_hz
        delivered = ~self._dropouts.covers(t)
        invalid = self._blinks.covers(t) | self._nan_bursts.covers(t)
        angles = np.zeros((len(t), 2))
        offsets = np.zeros((len(t), 2))
        distance = np.ones(len(t))
        order = np.argsort(which, kind="stable")  # each plan's ticks, ascending
        bounds = np.flatnonzero(np.diff(which[order])) + 1
        for rows in np.split(order, bounds) if len(order) else []:
            plan = plans[which[rows[0]]]
            t_rel = t[rows] - plan.start_s
            if plan.kind == "pursuit" and plan.target is not None:
                angles[rows] = self._pursuit(plan, t_rel)
            elif plan.kind == "free":
                angles[rows] = self._free_block(plan, t_rel)
            else:
                angles[rows] = plan.centre_deg
            offsets[rows] = self._plan_offset(plan)
            distance[rows] = plan.distance_m
        windows, index = np.divmod(ticks, 256)
        noise = np.empty((len(t), 3))
        edges = np.flatnonzero(np.diff(windows)) + 1  # ascending ticks: each window's rows are a run
        for first, stop in zip(np.concatenate([[0], edges]), np.concatenate([edges, [len(t)]])) if len(t) else []:
            span = slice(int(first), int(stop))
            self._noise(int(windows[first]) * 256)
            noise[span] = self._noise_cache[1][index[span]]  # type: ignore[index]  # _noise() just filled the cache
        ecc = np.hypot(angles[:, 0], angles[:, 1])
        err = offsets + self._error_grow_dir[None, :] * c.error_per_15deg * (ecc / 15.0)[:, None]
        drift = self._drift_dir[None, :] * (c.drift_start_deg + c.drift_deg_per_min * t / 60.0)[:, None]
        total = angles + noise[:, :2] + err + drift
        fixation = fick_direction(total[:, 0], total[:, 1]) * distance[:, None]
        fixation[invalid] = np.nan
        confidence = np.where(invalid, 0.0, np.clip(0.95 + 0.02 * noise[:, 2] / c.precision_deg, 0.0, 1.0))
        return SampleBlock(t, fixation, confidence, ~invalid, delivered)

    # model -------------------------------------------------------------------------
    def sample_at(self, t_s: float, tick: int) -> GazeSample:
        c = self.config
        if self._blinks.start_containing(t_s) is not None or self._nan_bursts.start_containing(t_s) is not None:
            return GazeSample(t_s, (math.nan, math.nan, math.nan), 0.0, False)
        plan = self._plan_at(t_s)
        az, el = self._eye_angles(plan, t_s)
        n0, n1, n2 = self._noise_row(tick)
        ecc = math.hypot(az, el)
        # the arithmetic of the 2-vectors err = offset + grow_dir * error_per_15deg * (ecc / 15) and
        # drift = drift_dir * (start + rate * t / 60), element by element in the same order (float64 either way)
        (o0, o1), (g0, g1), (d0, d1) = self._plan_offset_floats(plan), self._error_grow, self._drift
        grow, drifted = ecc / 15.0, c.drift_start_deg + c.drift_deg_per_min * t_s / 60.0
        az_deg = az + n0 + (o0 + g0 * c.error_per_15deg * grow) + d0 * drifted
        el_deg = el + n1 + (o1 + g1 * c.error_per_15deg * grow) + d1 * drifted
        f = _fick_direction_0d(az_deg, el_deg)
        d = plan.distance_m
        confidence = min(1.0, max(0.0, 0.95 + 0.02 * n2 / c.precision_deg))  # np.clip of a finite float
        return GazeSample(t_s, (f[0] * d, f[1] * d, f[2] * d), confidence, True)

    def _plan_offset(self, plan: FixationPlan) -> np.ndarray:
        """Per-plan error offset; the difference of two has mean norm ``error_centre_deg``. Drawn once per
        plan (its key), not per sample: the same numbers, without a numpy Generator per sample."""
        key = (int(round(plan.start_s * 1000.0)), plan.seed)
        if self._offset_cache is None or self._offset_cache[0] != key:
            self._offset_cache = (key, self._draw_plan_offset(*key))
        return self._offset_cache[1]

    def _draw_plan_offset(self, start_ms: int, plan_seed: int) -> np.ndarray:
        sigma = self.config.error_centre_deg / (math.sqrt(2.0) * math.sqrt(math.pi / 2.0))
        offset = self._scratch.at(self.seed, 8, start_ms, plan_seed).normal(0.0, sigma, 2)
        offset.setflags(write=False)  # shared by every sample of the plan
        return offset

    def _plan_offset_floats(self, plan: FixationPlan) -> tuple[float, float]:
        """:meth:`_plan_offset` as two Python floats (the same numbers), kept with the plan's key."""
        key = (int(round(plan.start_s * 1000.0)), plan.seed)
        cached = self._offset_floats
        if cached is None or cached[0] != key:
            o0, o1 = self._plan_offset(plan).tolist()
            self._offset_floats = cached = (key, (o0, o1))
        return cached[1]

    def _noise_row(self, tick: int) -> tuple[float, float, float]:
        """:meth:`_noise` of ``tick`` as three Python floats, drawing the window's table only as far as
        asked: its rows come from the window's generator in order (a normal draw holds no state between
        calls), so a prefix drawn now and the rows drawn on later equal the table :meth:`_noise` draws at once."""
        window, index = divmod(tick, 256)
        if self._noise_rows is None or self._noise_rows[0] != window:
            self._noise_generator.at(self.seed, 6, window)  # the window's stream, from its start
            self._noise_rows = (window, np.empty((0, 3)))
        drawn = self._noise_rows[1]
        if index >= len(drawn):
            more = self._noise_generator.generator.normal(0.0, self.config.precision_deg, (index + 1 - len(drawn), 3))
            drawn = np.concatenate([drawn, more]) if len(drawn) else more
            self._noise_rows = (window, drawn)
        n0, n1, n2 = drawn[index].tolist()
        return n0, n1, n2

    def _noise(self, tick: int) -> np.ndarray:
        """Three normal draws for ``tick`` (two angles scaled to the precision, one spare)."""
        window, index = divmod(tick, 256)
        if self._noise_cache is None or self._noise_cache[0] != window:
            table = self._scratch.at(self.seed, 6, window).normal(0.0, self.config.precision_deg, (256, 3))
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
        if plan.kind == "pursuit" and plan.target is not None:
            az, el = self._pursuit(plan, np.array([t_s - plan.start_s]))[0]
            return float(az), float(el)
        if plan.kind == "free":
            return self._free_viewing(plan, t_s - plan.start_s)
        return plan.centre_deg

    def _pursuit_params(self) -> PursuitParams:
        c = self.config
        return PursuitParams(c.pursuit_gain, c.pursuit_lag_s, c.catch_up_threshold_deg, c.main_sequence_vmax_deg_s,
                             c.main_sequence_c_deg)

    def catch_ups(self, plan: FixationPlan, until_rel_s: float) -> list[CatchUp]:
        """The catch-up saccades the simulated eye makes pursuing ``plan`` up to ``until_rel_s`` after its
        start (the ground truth recovery tests compare psyop's measures with)."""
        key = (int(round(plan.start_s * 1e6)), plan.seed, id(plan.target))
        cached = self._catch_up_cache
        if cached is None or cached[0] != key:
            rng = keyed_rng(self.seed, 9, key[0] & 0xFFFFFFFF, plan.seed)  # kept by the stream: a fresh one
            # catch_up_schedule found as far as asked (the same saccades; psyop.session.gaze.pursuit)
            self._catch_up_cache = cached = (key, CatchUpStream(self._positions(plan), self._pursuit_params(), rng))
        return cached[1].through(until_rel_s)

    @staticmethod
    def _positions(plan: FixationPlan) -> Callable[[np.ndarray], np.ndarray]:
        target = plan.target
        if isinstance(target, CirclingTarget):
            return target.positions
        assert target is not None

        def one_by_one(t: np.ndarray) -> np.ndarray:
            return np.array([target(float(x)) for x in np.asarray(t).reshape(-1)], dtype=np.float64).reshape(-1, 2)

        return one_by_one

    def _pursuit(self, plan: FixationPlan, t_rel_s: np.ndarray) -> np.ndarray:
        # the saccades begun by the last time asked: eye_positions reads no later one (the segment a time
        # lies in and the saccade after it, which has not begun, give the same positions with or without it)
        saccades = self.catch_ups(plan, float(np.max(t_rel_s)))
        return eye_positions(self._positions(plan), self._pursuit_params(), saccades, t_rel_s)

    def _free_block(self, plan: FixationPlan, t_rel_s: np.ndarray) -> np.ndarray:
        """:meth:`_free_viewing` at many times at once (the same arithmetic)."""
        self._free_viewing(plan, float(np.max(t_rel_s)), horizon_s=0.0)  # fills the fixation list far enough
        assert self._fixations is not None
        fixations = np.array(self._fixations[1])
        t = np.asarray(t_rel_s, dtype=np.float64)
        index = np.searchsorted(fixations[:, 0], np.maximum(t, 0.0), side="right") - 1
        out = fixations[index, 1:].copy()
        moving = (index > 0) & (t - fixations[index, 0] < self.config.saccade_s)
        if np.any(moving):
            w = ((t - fixations[index, 0]) / self.config.saccade_s)[moving, None]
            previous = fixations[index[moving] - 1, 1:]
            out[moving] = previous + w * (fixations[index[moving], 1:] - previous)
        return out

    def _free_viewing(self, plan: FixationPlan, t_rel_s: float, horizon_s: float = 10.0) -> tuple[float, float]:
        """The eye's (az, el) at ``t_rel_s`` into a free-viewing plan; the fixation list is drawn (in one
        sequence from the plan's seed: a longer list starts with the shorter) up to ``t_rel_s`` or ``horizon_s``."""
        c = self.config
        key = (plan.seed, plan.start_s)
        if self._fixations is None or self._fixations[0] != key or self._fixations[1][-1][0] < t_rel_s:
            rng = self._scratch.at(self.seed, 7, plan.seed)  # drawn here, at once
            starts, radii, polar, t = [], [], [], 0.0
            while t <= max(t_rel_s, horizon_s):
                starts.append(t)
                radii.append(plan.radius_deg * math.sqrt(rng.uniform()))
                polar.append(math.degrees(rng.uniform(0, 2 * math.pi)))
                t += rng.gamma(4.0, c.fixation_mean_s / 4.0)
            # r deg from the centre at polar angle a (docs/optics.md, "Angles"), as Fick angles: every fixation
            # at once (the same elementwise arithmetic as one at a time)
            az, el = fick_angles_deg(offset_direction(*plan.centre_deg, np.array(radii), np.array(polar)))
            self._fixations = (key, list(zip(starts, np.asarray(az).tolist(), np.asarray(el).tolist())))
        fixations = self._fixations[1]
        index = max(i for i, f in enumerate(fixations) if f[0] <= max(t_rel_s, 0.0))
        start, az, el = fixations[index]
        if index > 0 and t_rel_s - start < c.saccade_s:
            _, paz, pel = fixations[index - 1]
            w = (t_rel_s - start) / c.saccade_s
            return paz + w * (az - paz), pel + w * (el - pel)
        return az, el


def _fick_direction_0d(azimuth_deg: float, elevation_deg: float) -> tuple[float, float, float]:
    """:func:`psyop.optics.angles.fick_direction` of one direction, as floats: the same numpy functions on the
    same 0-d values (``angles_to_direction`` of two floats), without building arrays around them."""
    az = np.radians(np.float64(azimuth_deg))
    el = np.radians(np.float64(elevation_deg))
    cos_el = np.cos(el)
    return float(cos_el * np.sin(az) + 0.0), float(np.sin(el) + 0.0), float(-cos_el * np.cos(az) + 0.0)


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


#: the fields of ``observer: eye:`` (psyop.protocol.simulated_eye) that set a SimulatedTrackerConfig field
_EYE_FIELDS = ("rate_hz", "latency_s", "precision_deg", "pursuit_gain", "pursuit_lag_s", "catch_up_threshold_deg",
               "main_sequence_vmax_deg_s", "main_sequence_c_deg", "blink_rate_hz", "blink_s", "dropout_rate_hz",
               "dropout_s", "nan_burst_rate_hz", "nan_burst_s", "raw_stream", "error_centre_deg", "error_per_15deg",
               "drift_start_deg", "drift_deg_per_min")


def tracker_config(eye: SimulatedEye | None, participant: str,
                   base: SimulatedTrackerConfig | None = None) -> SimulatedTrackerConfig:
    """The simulated tracker of ``participant``: ``base`` (the command line's faults, else the defaults),
    then each field the protocol's ``observer: eye:`` sets, then its ``participants[participant]`` overrides.
    A fault rate the command line sets (``--sim-dropout-rate-hz``, ``--sim-nan-burst-rate-hz``) is kept
    when it is higher than the protocol's (a crash-safety test asks for faults); a ``raw_stream`` that
    ``base`` sets wins over the protocol's.

    Examples
    --------
    >>> from psyop.protocol.simulated_eye import SimulatedEye
    >>> eye = SimulatedEye(pursuit_gain=0.8, participants={"S02": {"dropout_rate_hz": 1.0}})
    >>> tracker_config(eye, "S01").pursuit_gain, tracker_config(eye, "S02").dropout_rate_hz
    (0.8, 1.0)
    """
    config = base or SimulatedTrackerConfig()
    if eye is None:
        return config
    values = {name: getattr(eye, name) for name in _EYE_FIELDS}  # every field of the typed section, by name
    override = eye.participants.get(participant)
    if override is not None:
        values.update({name: value for name, value in override.model_dump().items() if value is not None})
    values = {name: value for name, value in values.items() if value is not None}
    if config.raw_stream is not None:  # the caller's choice (psyop power never reads the raw stream)
        values.pop("raw_stream", None)
    for fault in ("dropout_rate_hz", "nan_burst_rate_hz"):
        if fault in values:
            values[fault] = max(values[fault], getattr(config, fault))
    return dataclasses.replace(config, **values)
