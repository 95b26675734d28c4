"""Per-frame gaze conditioning: hold the last valid gaze, and per-trial drift correction.

Why hold: a blink, NaN or low-confidence sample must not move the centre of
projection; the last good fixation is kept and the frame is flagged (``held``).
Why drift correction: at the start of each trial the observer fixates a cross at a
known direction; the measured direction's rotation away from it is removed from every
later sample of that trial (single-point recalibration, as in the paper).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from psyop.session.gaze.sample import GazeSample, angles_to_direction, direction_to_angles_deg, is_usable

#: Gaze used before any valid sample arrived: straight ahead at 1 m.
DEFAULT_FIXATION_M = (0.0, 0.0, -1.0)


@dataclass(frozen=True)
class ConditionedGaze:
    """The fixation the renderer uses for one frame, and where it came from."""

    fixation_m: tuple[float, float, float]
    sample_t_s: float
    confidence: float
    valid: bool
    held: bool


class GazeConditioner:
    """Holds the last valid fixation and applies the current drift correction."""

    def __init__(self, confidence_threshold: float = 0.6) -> None:
        self.confidence_threshold = confidence_threshold
        self._last: ConditionedGaze | None = None
        self._offset_az_deg = 0.0
        self._offset_el_deg = 0.0
        self._target: tuple[bytes, tuple[float, float]] | None = None  # the last target and its angles

    def recalibrate(self, measured: GazeSample | None, target_direction: np.ndarray) -> float:
        """Set the drift correction from one sample taken while fixating ``target_direction``.

        Returns the correction magnitude in degrees (nan and no change when unusable).
        """
        if measured is None or not measured.valid or not is_usable(measured.fixation_m, measured.confidence, self.confidence_threshold):
            return math.nan
        m_az, m_el = direction_to_angles_deg(measured.direction())
        t_az, t_el = self._target_angles(target_direction)
        self._offset_az_deg, self._offset_el_deg = t_az - m_az, t_el - m_el
        return math.hypot(self._offset_az_deg, self._offset_el_deg)

    def _target_angles(self, target_direction: np.ndarray) -> tuple[float, float]:
        """``direction_to_angles_deg(target_direction)``, kept for the last target (every trial's cross is the same)."""
        key = np.asarray(target_direction, dtype=np.float64).tobytes()  # bit for bit (a -0.0 is another target)
        if self._target is None or self._target[0] != key:
            self._target = (key, direction_to_angles_deg(target_direction))
        return self._target[1]

    def correct(self, fixation_m: tuple[float, float, float]) -> tuple[float, float, float]:
        f = np.asarray(fixation_m, dtype=np.float64)
        distance = float(np.sqrt(f.dot(f)))  # np.linalg.norm(f) of a 1-D float array, without its argument handling
        az, el = direction_to_angles_deg(f / distance)
        d = angles_to_direction(az + self._offset_az_deg, el + self._offset_el_deg) * distance
        return (float(d[0]), float(d[1]), float(d[2]))

    def condition(self, sample: GazeSample | None) -> ConditionedGaze:
        """The fixation to render with: this sample corrected, or the last valid one held."""
        if sample is not None and sample.valid and is_usable(sample.fixation_m, sample.confidence, self.confidence_threshold):
            self._last = ConditionedGaze(self.correct(sample.fixation_m), sample.timestamp_s, sample.confidence, True, False)
            return self._last
        t = sample.timestamp_s if sample is not None else math.nan
        conf = sample.confidence if sample is not None else 0.0
        if self._last is None:
            return ConditionedGaze(DEFAULT_FIXATION_M, t, conf, False, True)
        return ConditionedGaze(self._last.fixation_m, self._last.sample_t_s, conf, False, True)
