"""Protocol scene + trial row + time -> :mod:`psyop.rendering` scene (see docs/rendering.md)."""

from psyop.stimulus.build import INFINITY_M, build_scene, interval_mode, interval_phases

__all__ = ["INFINITY_M", "build_scene", "interval_mode", "interval_phases"]
