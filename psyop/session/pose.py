"""Hand (and head) pose for the egocentric study: simulated hand-tracker samples.

The paper tracked the hand with an HTC Vive Tracker at 120 Hz (1.9 mm RMSE accuracy,
1.5 mm precision) and took the reach as the mean of the last 10 samples (protocol
``response.average_last_samples``). The simulated hand ends its reach at the observer's
intended distance along the direction of the target and jitters with that precision.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Direction from the eyes' mid-point to the reach target: straight ahead, a little low.
REACH_DIRECTION = np.array([0.0, -0.15, -1.0]) / np.linalg.norm([0.0, -0.15, -1.0])


@dataclass(frozen=True)
class HandSamples:
    """Hand positions (head space, m) at the end of a reach, oldest first, and their times."""

    timestamps_s: np.ndarray
    positions_m: np.ndarray  # (n, 3)

    def reach_m(self, last_n: int) -> tuple[float, np.ndarray]:
        """Distance from the eyes' mid-point to the mean of the last ``last_n`` positions."""
        mean = self.positions_m[-last_n:].mean(axis=0)
        return float(np.linalg.norm(mean)), mean


def simulated_reach(intended_m: float, rng: np.random.Generator, *, n: int = 30, rate_hz: float = 120.0,
                    precision_m: float = 0.0015, accuracy_m: float = 0.0019, end_s: float = 0.0) -> HandSamples:
    """Samples of a hand held still at ``intended_m`` along :data:`REACH_DIRECTION`."""
    bias = rng.normal(0.0, accuracy_m / np.sqrt(3.0), 3)  # per-reach tracker accuracy error
    endpoint = REACH_DIRECTION * intended_m + bias
    positions = endpoint + rng.normal(0.0, precision_m / np.sqrt(3.0), (n, 3))
    times = end_s - (n - 1 - np.arange(n)) / rate_hz
    return HandSamples(times, positions)
