"""How many renderer primitives each scene item expands to, from the model alone (no rendering).

The counts mirror psyop.stimulus.build (tests/protocol/test_primitive_limit.py builds every kind and
compares); validation sums them per phase against psyop.limits.MAX_PRIMITIVES.
"""

from __future__ import annotations

from psyop.protocol.scene import (Aperture, Disc, FixationTarget, GridPlanes, Mesh, Primitive, Quad, ReachMesh,
                                  ReachTarget, Room,
                                  SinusoidalBorder, TargetField)

#: Room: floor, ceiling, two side walls, back wall; with a table also the table top, a plate and a bottle.
ROOM_WALLS = 5
ROOM_TABLE_ITEMS = 3


def primitive_count(item: Primitive) -> int:
    """The number of primitives ``item`` adds to a rendered scene (an aperture adds none)."""
    if isinstance(item, (Disc, Quad)):
        return 1
    if isinstance(item, (SinusoidalBorder, FixationTarget)):
        return 2  # near + far surface; outer + inner disc
    if isinstance(item, (Aperture, Mesh)):
        return 0  # a mesh is rasterised, outside the ray-caster's table (its budget: triangles)
    if isinstance(item, GridPlanes):
        return len(item.planes)
    if isinstance(item, TargetField):
        return int(item.count)
    if isinstance(item, Room):
        return ROOM_WALLS + (0 if item.table_height_m is None else ROOM_TABLE_ITEMS)
    if isinstance(item, ReachTarget):
        if isinstance(item.object, ReachMesh):
            return 0  # a model: rasterised, like a mesh item
        return 2 if item.object == "pencil" else 1  # body + tip
    raise TypeError(f"no primitive count for scene kind {type(item).__name__}")  # the model is a closed union
