"""The gaze sample every backend produces, and the interface of a gaze source."""

from __future__ import annotations

import collections
import math
import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from psyop.optics.angles import fick_angles_deg, fick_direction

if TYPE_CHECKING:
    from psyop.session.gaze.plan import FixationPlan
    from psyop.session.gaze.sync import ClockSync

_NAN3: tuple[float, float, float] = (math.nan, math.nan, math.nan)


class TrackerLost(RuntimeError):
    """The tracker stopped delivering samples for longer than the allowed gap."""


@dataclass(frozen=True)
class GazeSample:
    """One gaze estimate.

    ``timestamp_s`` is when the eye was in this state, on the session clock.
    ``fixation_m`` is the 3D fixation point in head space (x right, y up, -z forward,
    metres, relative to the mid-point between the eyes). ``valid`` is False for blinks,
    dropouts, NaN and low confidence.
    """

    timestamp_s: float
    fixation_m: tuple[float, float, float]
    confidence: float
    valid: bool

    @staticmethod
    def invalid(timestamp_s: float) -> GazeSample:
        return GazeSample(timestamp_s, (math.nan, math.nan, math.nan), 0.0, False)

    def direction(self) -> np.ndarray:
        """Unit gaze direction from the mid-point between the eyes."""
        f = np.asarray(self.fixation_m, dtype=np.float64)
        return f / np.sqrt(f.dot(f))  # np.linalg.norm(f) of a 1-D float array, without its argument handling


@dataclass(frozen=True, slots=True)
class EyeSample:
    """One eye's part of a raw tracker sample (NaN where the tracker does not give it).

    ``centre_m``: the eyeball centre (head space, m); ``normal``: the eye's unit gaze direction
    (head space); pupil diameter in mm (3-D eye model) and in eye-camera pixels (2-D)."""

    centre_m: tuple[float, float, float] = _NAN3
    normal: tuple[float, float, float] = _NAN3
    pupil_diameter_mm: float = math.nan
    pupil_diameter_px: float = math.nan


@dataclass(frozen=True, slots=True)
class RawGazeSample:
    """One sample exactly as a gaze source delivered it (the raw gaze stream, gaze.parquet).

    ``tracker_t_s``: the tracker's own timestamp (Pupil time, the sender's LSL clock, or the session
    clock for sources without their own); ``t_s``: that time on the session clock (after clock
    sync); ``received_s``: when the sample arrived (session clock). ``fixation_m``: the binocular
    fixation point (head space, m); ``norm_pos``: the tracker's 2-D gaze in its scene camera
    (normalised 0..1, x right, y up; NaN when not given); ``left``/``right``: per eye. ``valid`` is
    the source's verdict (finite, plausible time, confident enough) for this sample.
    See :data:`psyop.session.log.schema.GAZE_SCHEMA` for the logged columns.
    """

    tracker_t_s: float
    t_s: float
    received_s: float
    valid: bool
    confidence: float
    fixation_m: tuple[float, float, float] = _NAN3
    norm_pos: tuple[float, float] = (math.nan, math.nan)
    left: EyeSample | None = None
    right: EyeSample | None = None

    @staticmethod
    def of(sample: GazeSample, tracker_t_s: float | None = None, received_s: float | None = None) -> RawGazeSample:
        """The raw record of a source that delivers nothing beyond :class:`GazeSample`."""
        return RawGazeSample(sample.timestamp_s if tracker_t_s is None else tracker_t_s, sample.timestamp_s,
                             sample.timestamp_s if received_s is None else received_s, sample.valid,
                             sample.confidence, sample.fixation_m)


class GazeSource(Protocol):
    """What the loop needs from a tracker backend (every backend implements all of it).

    ``latest(now_s)`` returns the newest sample *available* at ``now_s`` (after the
    tracker's latency), or None before the first one. It raises :class:`TrackerLost`
    when the source is gone for longer than its allowed gap.

    ``set_plan(plan)`` says where the observer is asked to look from ``plan.start_s`` on: a
    simulated tracker follows it, a real tracker ignores it (a no-op).
    ``clock_sync()`` is the current tracker-to-session clock fit (None: samples are stamped on
    the session clock already); the runner records it per run.
    ``drain_raw()`` hands over every sample delivered since the last call, oldest first, and
    forgets them (the raw gaze stream; the session logs them durably with each trial).
    """

    def start(self) -> None: ...

    def latest(self, now_s: float) -> GazeSample | None: ...

    def set_plan(self, plan: FixationPlan) -> None: ...

    def clock_sync(self) -> ClockSync | None: ...

    def drain_raw(self) -> list[RawGazeSample]: ...

    def close(self) -> None: ...

    def stats(self) -> dict[str, float | int]: ...


class RawBuffer:
    """The samples a source delivered and the loop has not drained yet (thread-safe).

    ``limit``: at most this many are held (the oldest beyond it are dropped and counted in
    ``dropped``): a loop that never drains must not exhaust memory. A drained session never
    reaches it (the loop drains once per trial).

    Examples
    --------
    >>> buffer = RawBuffer()
    >>> buffer.add(RawGazeSample(1.0, 1.0, 1.0, True, 0.9))
    >>> [s.t_s for s in buffer.drain()], buffer.drain()
    ([1.0], [])
    """

    def __init__(self, limit: int = 2_000_000) -> None:
        self._lock = threading.Lock()
        self._samples: collections.deque[RawGazeSample] = collections.deque(maxlen=limit)
        self.dropped = 0
        self.total = 0

    def add(self, sample: RawGazeSample) -> None:
        with self._lock:
            if len(self._samples) == self._samples.maxlen:
                self.dropped += 1
            self._samples.append(sample)
            self.total += 1

    def drain(self) -> list[RawGazeSample]:
        with self._lock:
            samples = list(self._samples)
            self._samples.clear()
        return samples


def direction_to_angles_deg(direction: np.ndarray) -> tuple[float, float]:
    """Fick (azimuth, elevation) in degrees of a head-space direction (-z forward; docs/optics.md, "Angles")."""
    azimuth, elevation = fick_angles_deg(direction)
    return float(azimuth), float(elevation)


def angles_to_direction(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """Unit head-space direction of Fick (azimuth, elevation) in degrees (:func:`psyop.optics.angles.fick_direction`)."""
    return fick_direction(float(azimuth_deg), float(elevation_deg))


#: a fixation farther than this is not a measurement (``G 1e308 ...`` overflowed to NaN downstream)
MAX_FIXATION_DISTANCE_M = 1e5


def is_usable(fixation_m: tuple[float, float, float], confidence: float, threshold: float) -> bool:
    """Finite, in front of the eyes (z < 0), within :data:`MAX_FIXATION_DISTANCE_M` and confident enough."""
    x, y, z = fixation_m
    return bool(
        math.isfinite(x) and math.isfinite(y) and math.isfinite(z) and z < -1e-3
        and math.hypot(x, y, z) <= MAX_FIXATION_DISTANCE_M
        and math.isfinite(confidence) and confidence >= threshold
    )
