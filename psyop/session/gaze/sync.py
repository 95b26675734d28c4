"""Tracker clock -> session clock: the typed clock-sync record every live gaze source reports.

A tracker stamps samples on its own clock (Pupil time, the LSL clock of the sending host). The
source maps them onto the session clock with a line ``tracker = offset_s + (1 + drift) * local``
fitted from time pairs; session.json records the fit of every run (``runs[].clock_sync``) and
:meth:`psyop.session.gaze.sample.GazeSource.clock_sync` returns it (None: the source stamps
samples on the session clock itself, so there is nothing to synchronise).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np


@dataclass(frozen=True)
class ClockSync:
    """Tracker time = offset_s + (1 + drift) * local time; residual and round trips in s.

    ``method`` says how the pairs were measured (``pupil-remote-t``: Pupil Remote ``t`` round
    trips; ``lsl-time-correction``: liblsl's ``time_correction()``).

    Examples
    --------
    >>> sync = ClockSync(offset_s=100.0, drift=0.0, residual_sd_s=0.0, round_trip_median_s=1e-4, n=3)
    >>> sync.to_local(101.5)
    1.5
    """

    offset_s: float
    drift: float
    residual_sd_s: float
    round_trip_median_s: float
    n: int
    method: str = "pupil-remote-t"

    def to_local(self, tracker_t_s: float) -> float:
        """The session-clock time of a tracker timestamp."""
        return (tracker_t_s - self.offset_s) / (1.0 + self.drift)

    def to_tracker(self, local_t_s: float) -> float:
        """The tracker timestamp of a session-clock time (the inverse of :meth:`to_local`)."""
        return self.offset_s + (1.0 + self.drift) * local_t_s

    def stepped(self, step_s: float) -> ClockSync:
        """This fit after the tracker's timestamps stepped by ``step_s`` (a clock jump: negative
        back, positive forward): the same drift and quality, the offset moved by the step, so a
        stamp from after the step maps to the session time it would have had without it.

        Examples
        --------
        >>> sync = ClockSync(offset_s=100.0, drift=0.0, residual_sd_s=0.0, round_trip_median_s=1e-4, n=3)
        >>> sync.stepped(-5.0).to_local(96.5)  # stamps now run 5 s behind: 96.5 is what 101.5 was
        1.5
        """
        return replace(self, offset_s=self.offset_s + step_s)

    def as_dict(self) -> dict[str, float | int | str | None]:
        """What session.json records (``runs[].clock_sync``); a value the method does not measure
        (liblsl's ``time_correction()`` reports no round trip) is null, never NaN in the JSON."""
        def finite(value: float) -> float | None:
            return value if math.isfinite(value) else None

        return {"offset_s": self.offset_s, "drift": self.drift, "residual_sd_s": finite(self.residual_sd_s),
                "round_trip_median_s": finite(self.round_trip_median_s), "n": self.n, "method": self.method}


def fit_clock_sync(local_mid_s: np.ndarray, remote_s: np.ndarray, round_trips_s: np.ndarray, *,
                   min_span_s: float = 1.0, method: str = "pupil-remote-t") -> ClockSync:
    """Least-squares line through (local, remote) time pairs.

    Drift is only estimated once the pairs span ``min_span_s``: over a few milliseconds
    of round trips the slope is pure noise. Before that the slope is fixed to 1 and the
    offset is the mean over the faster half of the round trips (least queueing).

    Examples
    --------
    >>> local = np.array([0.0, 0.5, 1.0, 1.5])
    >>> sync = fit_clock_sync(local, local + 10.0, np.full(4, 1e-4))
    >>> round(sync.offset_s, 9), round(sync.drift, 9)
    (10.0, 0.0)
    """
    local_mid_s = np.asarray(local_mid_s, dtype=np.float64)
    remote_s = np.asarray(remote_s, dtype=np.float64)
    trips = np.asarray(round_trips_s, dtype=np.float64)
    if local_mid_s.size >= 3 and np.ptp(local_mid_s) >= min_span_s:
        x0 = local_mid_s.mean()
        slope, intercept = np.polyfit(local_mid_s - x0, remote_s, 1)
        offset = intercept - slope * x0
    else:
        fast = trips <= np.median(trips)
        slope, offset = 1.0, float(np.mean((remote_s - local_mid_s)[fast]))
    residual = remote_s - (offset + slope * local_mid_s)
    return ClockSync(float(offset), float(slope - 1.0), float(np.std(residual)), float(np.median(trips)),
                     int(local_mid_s.size), method)
