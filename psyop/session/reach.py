"""Reach along the horizontal eye-to-target direction.

The paper's supplement (Egocentric depth, Analysis): "the data was analyzed along the
horizontal 2D vector between the eyes' midpoint and the target's position. Both the
target's distance and reach distance were computed along this vector." psyop's reach
targets (:class:`psyop.protocol.scene.ReachTarget`) sit straight ahead of the eyes'
mid-point (x = 0) at ``distance_fraction * arm_reach_m`` along -z and ``height_m`` below
the eyes, so the target distance is already horizontal and the reach is the hand's
component along the same horizontal unit vector. The 3-D eye-to-hand distance would
differ by the hand's height below the eyes (about 1 % in slope at the paper's distances).
"""

from __future__ import annotations

import numpy as np

from psyop.protocol.kinds.reach import HAND_HEIGHT_M  # ReachTarget's default height, where a simulated hand ends

#: Head space: x right, y up, -z ahead. ReachTarget objects are straight ahead, at HAND_HEIGHT_M.
TARGET_POSITION_M = (0.0, HAND_HEIGHT_M, -1.0)

__all__ = ["HAND_HEIGHT_M", "TARGET_POSITION_M", "horizontal_direction", "horizontal_reach_m"]


def horizontal_direction(target_m=TARGET_POSITION_M) -> np.ndarray:
    """Unit vector from the eyes' mid-point towards the target, with its vertical part removed."""
    t = np.asarray(target_m, dtype=np.float64)
    h = np.array([t[0], 0.0, t[2]])
    norm = float(np.linalg.norm(h))
    if norm == 0.0:
        raise ValueError("the target is straight above or below the eyes: no horizontal direction")
    return h / norm


def horizontal_reach_m(hand_m, target_m=TARGET_POSITION_M) -> float:
    """The hand's distance from the eyes' mid-point along the horizontal eye-to-target direction."""
    return float(np.dot(np.asarray(hand_m, dtype=np.float64), horizontal_direction(target_m)))
