"""Which frames ``psyop audit`` renders: every condition x phase x eye x gaze.

One representative trial per condition (its first non-practice trial in the schedule of the
given seed), each phase of it that draws the stimulus (every interval in its rendering mode,
and a blank phase that shows primitives, e.g. the realism study's grid, in its own mode), each
eye the protocol shows, and ``gazes`` gaze directions: along the fixation target's path when the scene has a
moving fixation target (the target's position at ``k / gazes`` of the interval), otherwise a
grid (straight ahead, then a ring at :data:`GRID_ECCENTRICITY_DEG`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from psyop.rendering.builders import direction_from_angles
from psyop.stimulus.placement import polar_centre_deg
from psyop.records import JsonObject, TrialRow

if TYPE_CHECKING:
    import pandas as pd

    from psyop.rendering.scene import Scene

GRID_ECCENTRICITY_DEG = 10.0
GRID_FIXATION_DISTANCE_M = 1.0


@dataclass(frozen=True)
class AuditFrame:
    """One frame to check. ``phase``: the plan phase's name (``interval<k>`` or ``blank``);
    ``interval``: whose factor values the scene uses; ``phase_index``: its place in the trial.
    ``gaze_index`` numbers the gazes of a (condition, phase, eye); the same index means the same
    gaze and time in every phase."""

    condition: str
    trial: int
    row: TrialRow
    phase: str
    phase_index: int
    interval: int
    mode: str
    eye: str
    gaze_index: int
    time_s: float

    @property
    def is_interval(self) -> bool:
        return self.phase.startswith("interval")

    @property
    def label(self) -> str:
        return (f"condition {self.condition}, trial {self.trial}, {self.phase} ({self.mode}), "
                f"{self.eye} eye, gaze {self.gaze_index} (t = {self.time_s:.3g} s)")


def representative_rows(schedule: pd.DataFrame) -> list[JsonObject]:
    """The first trial of each condition, non-practice trials preferred, in schedule order."""
    rows: dict[str, JsonObject] = {}
    for row in schedule.to_dict("records"):
        key = str(row["condition"])
        if key not in rows or (rows[key].get("practice") and not row.get("practice")):
            rows[key] = row
    return sorted(rows.values(), key=lambda r: int(r["trial"]))


def grid_gaze_deg(index: int, count: int) -> tuple[float, float]:
    """Gaze ``index`` of ``count`` on the grid as Fick angles: straight ahead, then evenly round a ring of
    constant eccentricity ``GRID_ECCENTRICITY_DEG`` (docs/optics.md, "Angles")."""
    if index == 0:
        return (0.0, 0.0)
    meridian_deg = 360.0 * (index - 1) / max(1, count - 1)
    return polar_centre_deg(GRID_ECCENTRICITY_DEG, meridian_deg)


def fixation_point(scene: Scene, fixation_prefix: str | None, origin_m: np.ndarray, gaze_index: int,
                   gaze_count: int) -> np.ndarray:
    """Where the eyes fixate in this frame, head space: the fixation target's centre ((4,) with
    w = 0 when it is at optical infinity), else a grid point ``GRID_FIXATION_DISTANCE_M`` from
    the scene origin."""
    if fixation_prefix is not None:
        for prim in scene.primitives:
            if prim.name == f"{fixation_prefix}_outer":
                if prim.at_infinity:
                    return np.array([*prim.centre_m, 0.0])
                return np.asarray(prim.centre_m, dtype=np.float64)
    direction = direction_from_angles(*grid_gaze_deg(gaze_index, gaze_count))
    return origin_m + direction * (GRID_FIXATION_DISTANCE_M / -direction[2])
