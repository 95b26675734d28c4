"""The simulated eye's smooth pursuit with catch-up saccades (a pure function of the plan and its seed).

Model (stated, and what :mod:`psyop.quality` recovers):

- The eye sees the target ``lag_s`` late: it follows ``T(t - lag_s)`` (Fick angles, degrees; the target
  holds its start position before ``lag_s``).
- Smooth pursuit with gain ``g``: between saccades the eye's velocity is ``g`` times the (late)
  target's velocity, ``E(t) = E(s_n) + g * (T(t - lag) - T(s_n - lag))`` from the end ``s_n`` of the
  last saccade; so its position error against the late target grows as ``(1 - g)`` times the
  target's path since then.
- A catch-up saccade starts when that error reaches a threshold (``threshold_deg`` times a factor
  drawn uniformly from 0.8..1.2 per saccade). It lands on the late target at its end. Its amplitude
  ``A`` and peak velocity follow the main sequence ``V_peak = vmax * (1 - exp(-A / c))``
  (Baloh et al. 1975's form), with a raised-cosine velocity profile, so its duration is
  ``2 A / V_peak``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

Positions = Callable[[np.ndarray], np.ndarray]  # t_rel_s (n,) -> Fick (az, el) degrees (n, 2)


@dataclass(frozen=True)
class PursuitParams:
    gain: float
    lag_s: float
    threshold_deg: float
    vmax_deg_s: float
    c_deg: float


@dataclass(frozen=True)
class CatchUp:
    """One catch-up saccade: onset (s after the plan's start), duration (s), start and landing (deg)."""

    onset_s: float
    duration_s: float
    start_deg: tuple[float, float]
    land_deg: tuple[float, float]

    @property
    def amplitude_deg(self) -> float:
        return math.hypot(self.land_deg[0] - self.start_deg[0], self.land_deg[1] - self.start_deg[1])

    @property
    def peak_velocity_deg_s(self) -> float:
        return 2.0 * self.amplitude_deg / self.duration_s


def main_sequence_peak_deg_s(amplitude_deg: float, vmax_deg_s: float, c_deg: float) -> float:
    """Peak velocity of a saccade of ``amplitude_deg`` (main sequence)."""
    return vmax_deg_s * (1.0 - math.exp(-amplitude_deg / c_deg))


def _late(target: Positions, t_rel_s: np.ndarray, lag_s: float) -> np.ndarray:
    return target(np.maximum(0.0, np.asarray(t_rel_s, dtype=np.float64) - lag_s))


def catch_up_schedule(target: Positions, p: PursuitParams, horizon_s: float, rng: np.random.Generator) -> list[CatchUp]:
    """The catch-up saccades of a pursuit from its start to ``horizon_s`` (deterministic in ``rng``); onsets
    and landings lie on a 0.5 ms grid (the target is evaluated on it once)."""
    saccades: list[CatchUp] = []
    if p.gain >= 1.0 or p.threshold_deg <= 0.0:
        return saccades
    step = 0.0005
    grid = np.arange(int(math.ceil((horizon_s + 1.0) / step)) + 1) * step
    late = _late(target, grid, p.lag_s)
    last = len(grid) - 1
    i_n, e_n = 0, late[0]  # grid index where the current smooth segment starts, and the eye there
    while grid[i_n] < horizon_s:
        threshold = p.threshold_deg * rng.uniform(0.8, 1.2)
        error = (1.0 - p.gain) * np.hypot(*(late[i_n + 1:i_n + 4001] - late[i_n]).T)  # 2 s ahead
        over = np.flatnonzero(error >= threshold)
        if not len(over):
            break
        i_on = i_n + 1 + int(over[0])
        start = e_n + p.gain * (late[i_on] - late[i_n])
        i_land = min(last, i_on + 60)  # a first guess of 30 ms
        for _ in range(3):  # the duration from the amplitude to where it lands at its end
            amplitude = float(np.hypot(*(late[i_land] - start)))
            duration = 2.0 * amplitude / max(main_sequence_peak_deg_s(amplitude, p.vmax_deg_s, p.c_deg), 1e-9)
            i_land = min(last, i_on + max(1, int(round(duration / step))))
        land = late[i_land]
        saccades.append(CatchUp(float(grid[i_on]), float(grid[i_land] - grid[i_on]), (float(start[0]), float(start[1])),
                                (float(land[0]), float(land[1]))))
        i_n, e_n = i_land, land
        if i_n >= last:
            break
    return saccades


class CatchUpStream:
    """:func:`catch_up_schedule` on demand: the saccades of one pursuit, found only as far as a caller asks
    (:meth:`through`) and extended when a later time is asked. The same saccades as
    ``catch_up_schedule(target, p, horizon_s, rng)`` for every onset up to the time asked (and any
    ``horizon_s`` above it): the same grid values (``index * step``), the target evaluated on it chunk by chunk
    (elementwise: the same numbers as on the whole grid), the same first threshold crossing searched chunk by
    chunk (a search stopped at the time asked resumes there, its threshold kept) and the same draws from ``rng``,
    in order (tests/session/test_catch_up_stream.py compares them)."""

    _CHUNK = 512  # grid points per evaluation of the target (0.256 s)
    _STEP = 0.0005
    _AHEAD = 4000  # how far a search looks for the next onset (2 s), as catch_up_schedule
    _MARGIN = 128  # grid points evaluated past the time asked (a saccade begun by then lands after it)

    def __init__(self, target: Positions, p: PursuitParams, rng: np.random.Generator) -> None:
        self._target, self._p, self._rng = target, p, rng
        self.saccades: list[CatchUp] = []
        self._late = np.empty((0, 2))  # the late target on the grid, as far as evaluated (_late_to)
        self._i_n, self._e_n = 0, np.zeros(2)  # the eye at the current segment's start (set on the first call)
        self._done = p.gain >= 1.0 or p.threshold_deg <= 0.0
        self._pending: tuple[float, int] | None = None  # a search begun: its threshold and the next index to scan

    def _late_to(self, n: int) -> np.ndarray:
        """The late target on the grid, at least its first ``n`` points."""
        have = len(self._late)
        if have < n:
            more = max(n - have, self._CHUNK)
            extra = _late(self._target, np.arange(have, have + more) * self._STEP, self._p.lag_s)
            self._late = np.concatenate([self._late, extra]) if have else extra
        return self._late

    def through(self, until_rel_s: float) -> list[CatchUp]:
        """The saccades whose onset is at most ``until_rel_s`` (s after the pursuit's start)."""
        # the last grid index a search must reach (one past int(until / step): round-off never hides an onset)
        last = max(0, int(until_rel_s / self._STEP)) + 1
        started = len(self._late) > 0
        late = self._late_to(last + self._MARGIN)  # the grid asked, in one evaluation
        if not started:
            self._e_n = late[0]  # the eye starts on the late target
        while not self._done and self._i_n * self._STEP <= until_rel_s and self._next(last):
            pass
        return [s for s in self.saccades if s.onset_s <= until_rel_s]

    def _onset(self, threshold: float, first: int, last: int) -> int | None:
        """The grid index of the first crossing of ``threshold`` from ``first`` to ``last`` (inclusive) in the
        current search window, or None."""
        i_n, gain = self._i_n, self._p.gain
        for a in range(first, last + 1, self._CHUNK):
            b = min(a + self._CHUNK, last + 1)
            late = self._late_to(b)
            error = (1.0 - gain) * np.hypot(*(late[a:b] - late[i_n]).T)
            over = np.flatnonzero(error >= threshold)
            if len(over):
                return a + int(over[0])
        return None

    def _next(self, last: int) -> bool:
        """Search the next onset up to grid index ``last``: True when a saccade was added; False when none
        begins by then (the search, its threshold drawn, resumes there when a later time is asked) or at all."""
        p, step = self._p, self._STEP
        if self._pending is None:  # a new search: its threshold (one draw, in order)
            self._pending = (p.threshold_deg * self._rng.uniform(0.8, 1.2), self._i_n + 1)
        threshold, first = self._pending
        window_end = self._i_n + self._AHEAD  # the search window's last index, as catch_up_schedule
        stop = min(window_end, last)
        i_on = self._onset(threshold, first, stop)
        if i_on is None:
            if stop == window_end:
                self._done = True  # no crossing in the whole window: catch_up_schedule ends there
            else:
                self._pending = (threshold, stop + 1)
            return False
        self._pending = None
        late = self._late
        start = self._e_n + p.gain * (late[i_on] - late[self._i_n])
        i_land = i_on + 60  # a first guess of 30 ms
        for _ in range(3):  # the duration from the amplitude to where it lands at its end
            late = self._late_to(i_land + 1)
            amplitude = float(np.hypot(*(late[i_land] - start)))
            duration = 2.0 * amplitude / max(main_sequence_peak_deg_s(amplitude, p.vmax_deg_s, p.c_deg), 1e-9)
            i_land = i_on + max(1, int(round(duration / step)))
        land = self._late_to(i_land + 1)[i_land]
        t_on, t_land = i_on * step, i_land * step
        self.saccades.append(CatchUp(float(t_on), float(t_land - t_on), (float(start[0]), float(start[1])),
                                     (float(land[0]), float(land[1]))))
        self._i_n, self._e_n = i_land, land
        return True


def eye_positions(target: Positions, p: PursuitParams, saccades: list[CatchUp], t_rel_s: np.ndarray) -> np.ndarray:
    """Fick (az, el) of the pursuing eye at ``t_rel_s`` (s after the plan's start); shape (n, 2)."""
    t = np.asarray(t_rel_s, dtype=np.float64)
    onsets = np.array([s.onset_s for s in saccades] + [math.inf])
    ends = np.array([0.0] + [s.onset_s + s.duration_s for s in saccades])
    n = np.searchsorted(ends, t, side="right") - 1  # the smooth segment begun last (index into ends)
    n = np.clip(n, 0, len(ends) - 1)
    seg_start = ends[n]
    # the late target at t, at the segments' starts and at 0 in one evaluation (elementwise: the same numbers)
    count = t.size
    late_all = _late(target, np.concatenate([t.reshape(-1), seg_start.reshape(-1), [0.0]]), p.lag_s)
    late, late_seg = late_all[:count], late_all[count:2 * count]
    e_start = np.array([late_all[-1]] + [np.array(s.land_deg) for s in saccades])
    out = e_start[n] + p.gain * (late - late_seg)
    in_saccade = t >= onsets[n]
    if np.any(in_saccade):
        k = n[in_saccade]
        u = (t[in_saccade] - onsets[k]) / np.array([saccades[i].duration_s for i in k])
        shape = (u - np.sin(2.0 * np.pi * u) / (2.0 * np.pi))[:, None]
        start = np.array([saccades[i].start_deg for i in k])
        land = np.array([saccades[i].land_deg for i in k])
        out[in_saccade] = start + (land - start) * shape
    return out
