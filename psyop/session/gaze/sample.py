"""The gaze sample every backend produces, and the interface of a gaze source."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from psyop.optics.angles import fick_angles_deg, fick_direction


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
        return f / np.linalg.norm(f)


class GazeSource(Protocol):
    """What the loop needs from a tracker backend.

    ``latest(now_s)`` returns the newest sample *available* at ``now_s`` (after the
    tracker's latency), or None before the first one. It raises :class:`TrackerLost`
    when the source is gone for longer than its allowed gap.
    """

    def start(self) -> None: ...

    def latest(self, now_s: float) -> GazeSample | None: ...

    def close(self) -> None: ...

    def stats(self) -> dict[str, float | int]: ...


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
