"""Protocol scene + trial row + time -> :mod:`psyop.rendering` scene (see docs/rendering.md)."""

from psyop.stimulus.build import (
    INFINITY_M,
    blank_scene,
    build_scene,
    interval_mode,
    interval_phases,
    recalibration_cross_scene,
    scene_origin_m,
    text_scene,
)

__all__ = [
    "INFINITY_M", "blank_scene", "build_scene", "interval_mode", "interval_phases", "recalibration_cross_scene",
    "scene_origin_m", "text_scene",
]
