"""The contact sheet's crop: the part of every audited frame where the scene's primitives are, rendered again with
finer pixels so a few-degree stimulus is legible (at the audit's 1/8 scale a 6 deg disc is ~10 pixels wide).

The crop is one window for the whole sheet (every cell shows the same part of the field, so cells compare): the union
of the primitives' conservative screen boxes (psyop.audit.masks.screen_boxes_px) over all frames, padded by
:data:`PAD_FRACTION`. Its frames are rendered through the same rays on a finer grid
(psyop.audit.masks.zoom_camera), at a magnification that makes the window's longer side at least
:data:`TARGET_PX` pixels, but never finer than the display's own pixels (so a cell never shows detail the
participant's display cannot). No crop (whole frames, as before) when a primitive is unbounded on screen (a grid,
a room), or the window covers most of the frame anyway.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from psyop.rendering.screen_bounds import UNBOUNDED_PX

#: the crop window's longer side, in sheet pixels, that the magnification aims for
TARGET_PX = 240
#: the window is the primitives' union grown by this fraction of its size on every side (at least 2 pixels)
PAD_FRACTION = 0.15
#: a window covering more than this share of the frame is not cropped
MAX_FRAME_SHARE = 0.5


@dataclass(frozen=True)
class SheetCrop:
    """The window ``x0 .. x0 + width_px``, ``y0 .. y0 + height_px`` of every audited frame (audit pixels), rendered
    with ``magnification`` x ``magnification`` pixels per audit pixel."""

    x0: int
    y0: int
    width_px: int
    height_px: int
    magnification: int

    def describe(self, scale: float) -> str:
        """The window in the display's own pixels, for the sheet's title."""
        to_display = 1.0 / scale
        return (f"crop x {self.x0 * to_display:.0f}-{(self.x0 + self.width_px) * to_display:.0f}, "
                f"y {self.y0 * to_display:.0f}-{(self.y0 + self.height_px) * to_display:.0f} display px, "
                f"{self.magnification} x the audit's pixels")


def sheet_crop(boxes: Sequence[np.ndarray], width_px: int, height_px: int, scale: float) -> SheetCrop | None:
    """The one window covering every frame's primitive boxes ((n, 4) x_min, y_min, x_max, y_max each), or None.

    Examples
    --------
    >>> sheet_crop([np.array([[80.0, 90.0, 100.0, 110.0]])], 180, 200, 0.125)
    SheetCrop(x0=77, y0=87, width_px=26, height_px=26, magnification=8)
    >>> sheet_crop([np.array([[0.0, 0.0, UNBOUNDED_PX, 10.0]])], 180, 200, 0.125) is None  # a grid plane
    True
    """
    stacked = [b for b in boxes if len(b)]
    if not stacked:
        return None
    every = np.concatenate(stacked)
    if not np.all(np.abs(every) < UNBOUNDED_PX):
        return None
    x_min, y_min = max(float(every[:, 0].min()), 0.0), max(float(every[:, 1].min()), 0.0)
    x_max, y_max = min(float(every[:, 2].max()), float(width_px)), min(float(every[:, 3].max()), float(height_px))
    if x_max <= x_min or y_max <= y_min:
        return None
    pad = max(2.0, PAD_FRACTION * max(x_max - x_min, y_max - y_min))
    x0, y0 = max(0, math.floor(x_min - pad)), max(0, math.floor(y_min - pad))
    x1, y1 = min(width_px, math.ceil(x_max + pad)), min(height_px, math.ceil(y_max + pad))
    if (x1 - x0) * (y1 - y0) > MAX_FRAME_SHARE * width_px * height_px:
        return None
    finest = max(1, round(1.0 / scale))
    magnification = max(1, min(finest, math.ceil(TARGET_PX / max(x1 - x0, y1 - y0))))
    return SheetCrop(x0, y0, x1 - x0, y1 - y0, magnification)
