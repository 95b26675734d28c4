"""What the observer is asked to look at during a trial phase (drives simulated gaze)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from psyop.session.gaze.sample import angles_to_direction


@dataclass(frozen=True)
class FixationPlan:
    """Where gaze should go from ``start_s`` (session clock) on.

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
            return angles_to_direction(*self.target(t_s - self.start_s))
        return angles_to_direction(*self.centre_deg)


def circling_target(eccentricity_deg: float = 16.0, speed_deg_s: float = 90.0, phase_deg: float = 0.0) -> Callable[[float], tuple[float, float]]:
    """A target circling the centre at ``eccentricity_deg`` (the threshold studies' fixation target).

    ``speed_deg_s`` is the angular speed of the target around the circle.
    """

    def position(t_rel_s: float) -> tuple[float, float]:
        angle = np.radians(phase_deg + speed_deg_s * t_rel_s)
        return float(eccentricity_deg * np.cos(angle)), float(eccentricity_deg * np.sin(angle))

    return position
