"""The frame that marks the location an n_afc's stick highlights (psyop.session.rating_stick): four thin yellow bars,
:data:`MARKER_SIZE_DEG` across, around the location's direction from the scene origin, in front of the response
text panel (:data:`MARKER_DISTANCE_M`, nearer than the panel's 1 m, so the nearest-hit renderer draws it over the
panel where they overlap). It is head-fixed with the panel it is drawn with.
"""

from __future__ import annotations

from collections.abc import Sequence

from psyop.rendering.builders import frontoparallel_rect
from psyop.rendering.scene import Primitive, Scene, Solid

#: the frame's outer size (deg across and up), its bars' width (deg) and colour
MARKER_SIZE_DEG, MARKER_BAR_DEG = 4.0, 0.3
MARKER_RGB = (1.0, 0.85, 0.0)  # yellow: apart from the white text of a panel it may lie on
#: how far ahead of the scene origin the frame is drawn: in front of the response text (psyop.stimulus.build's
#: TEXT_DISTANCE_M, 1 m)
MARKER_DISTANCE_M = 0.9
#: the name of each of the frame's bars in the scene (a frame check or a test finds them by it)
MARKER_NAME = "choice_marker"


def marker_frame(marker_deg: tuple[float, float], origin_m: Sequence[float]) -> tuple[Primitive, ...]:
    """The four bars (left, right, bottom, top) of the frame around Fick [azimuth, elevation] ``marker_deg`` seen from
    ``origin_m`` (head space, m)."""
    azimuth, elevation = float(marker_deg[0]), float(marker_deg[1])
    half = (MARKER_SIZE_DEG - MARKER_BAR_DEG) / 2.0
    ink = Solid(MARKER_RGB)
    sides = ((-half, 0.0, MARKER_BAR_DEG, MARKER_SIZE_DEG), (half, 0.0, MARKER_BAR_DEG, MARKER_SIZE_DEG),
             (0.0, -half, MARKER_SIZE_DEG, MARKER_BAR_DEG), (0.0, half, MARKER_SIZE_DEG, MARKER_BAR_DEG))
    return tuple(frontoparallel_rect(MARKER_DISTANCE_M, width, height, ink, azimuth + d_az, elevation + d_el,
                                     origin_m=tuple(float(c) for c in origin_m), name=MARKER_NAME)
                 for d_az, d_el, width, height in sides)


def with_marker(scene: Scene, marker_deg: tuple[float, float] | None, origin_m: Sequence[float]) -> Scene:
    """``scene`` with the frame around ``marker_deg`` added (None: ``scene`` as it is)."""
    if marker_deg is None:
        return scene
    return Scene(scene.primitives + marker_frame(marker_deg, origin_m), background=scene.background,
                 aperture=scene.aperture, meshes=scene.meshes, output=scene.output)
