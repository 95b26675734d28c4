"""What the observer is asked to look at during a trial phase (drives simulated gaze)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from psyop.optics.angles import fick_direction, offset_frame
from psyop.stimulus.placement import circle_position_deg


@dataclass(frozen=True, slots=True)  # slots: the loop makes one per phase of every trial
class FixationPlan:
    """Where gaze should go from ``start_s`` (session clock) on.

    Angles are Fick (azimuth, elevation) in degrees (docs/optics.md, "Angles").
    kind: 'cross' (fixate ``centre_deg``), 'pursuit' (follow ``target(t_rel_s) ->
    (az_deg, el_deg)``), 'free' (saccades between random points within ``radius_deg`` of
    ``centre_deg``), 'none' (display off: look ahead).
    """

    kind: str
    start_s: float
    distance_m: float = 1.0
    centre_deg: tuple[float, float] = (0.0, 0.0)
    radius_deg: float = 10.0
    target: Callable[[float], tuple[float, float]] | None = None
    seed: int = 0

    def target_direction(self, t_s: float) -> np.ndarray:
        """Intended gaze direction at session time ``t_s`` (cross/none: the centre)."""
        if self.kind == "pursuit" and self.target is not None:
            az_deg, el_deg = self.target(t_s - self.start_s)
        else:
            az_deg, el_deg = self.centre_deg
        return fick_direction(float(az_deg), float(el_deg))  # as gaze.sample.angles_to_direction (no import back)


@dataclass(frozen=True)
class CirclingTarget:
    """A target circling ``centre_deg`` (Fick angles) at constant ``eccentricity_deg``, its polar angle
    ``phase_deg + speed_deg_s * t`` (:func:`psyop.stimulus.placement.circle_position_deg`, the one path the
    stimulus draws). Called with a time it returns Fick (az, el); :meth:`positions` does many at once."""

    eccentricity_deg: float
    speed_deg_s: float
    phase_deg: float
    centre_deg: tuple[float, float]

    def __call__(self, t_rel_s: float) -> tuple[float, float]:
        return circle_position_deg(self.centre_deg[0], self.centre_deg[1], self.eccentricity_deg, self.phase_deg,
                                   self.speed_deg_s, t_rel_s)

    @cached_property
    def _frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The offset frame of the centre and eccentricity (:func:`psyop.optics.angles.offset_frame`), once:
        the simulated eye evaluates the target thousands of times per pursuit."""
        return offset_frame(self.centre_deg[0], self.centre_deg[1], self.eccentricity_deg)

    def positions(self, t_rel_s: np.ndarray) -> np.ndarray:
        """Fick (az, el) at each of ``t_rel_s``; shape (n, 2) (equal to calling it per time, to round-off).

        ``fick_angles_deg(offset_direction_in(self._frame, polar))`` computed one direction component at a
        time (each the same elementwise operations, so the same numbers: tests/session/test_circling_positions.py),
        without the (n, 3) temporaries: the simulated eye evaluates thousands of times per pursuit."""
        polar = self.phase_deg + self.speed_deg_s * np.asarray(t_rel_s, dtype=np.float64).reshape(-1)
        ahead, sin_ecc, right, up = self._frame  # offset_direction(*centre_deg, eccentricity_deg, polar)
        mer = np.radians(polar)
        cos_mer, sin_mer = np.cos(mer), np.sin(mer)
        se = sin_ecc.reshape(-1)[0]
        x = ahead[0] + se * (cos_mer * right[0] + sin_mer * up[0])
        y = ahead[1] + se * (cos_mer * right[1] + sin_mer * up[1])
        z = ahead[2] + se * (cos_mer * right[2] + sin_mer * up[2])
        out = np.empty((len(polar), 2))
        np.degrees(np.arctan2(x, -z), out=out[:, 0])  # fick_angles_deg: azimuth, then elevation
        np.degrees(np.arctan2(y, np.hypot(x, z)), out=out[:, 1])
        return out


def circling_target(eccentricity_deg: float = 16.0, speed_deg_s: float = 90.0, phase_deg: float = 0.0,
                    centre_deg: tuple[float, float] = (0.0, 0.0)) -> CirclingTarget:
    """A target circling ``centre_deg`` (Fick angles) at constant ``eccentricity_deg`` (the threshold
    studies' fixation target), the one path the stimulus draws (:func:`psyop.stimulus.placement.circle_position_deg`).

    ``speed_deg_s`` is the rate of the polar angle around the circle (negative: clockwise); the
    target's own angular speed is ``|speed_deg_s| * sin(eccentricity_deg)``. Returns Fick (az, el).

    Examples
    --------
    >>> az, el = circling_target(16.0, 90.0)(1.0)
    >>> round(az, 9), round(el, 9)
    (0.0, 16.0)
    """
    return CirclingTarget(float(eccentricity_deg), float(speed_deg_s), float(phase_deg),
                          (float(centre_deg[0]), float(centre_deg[1])))
