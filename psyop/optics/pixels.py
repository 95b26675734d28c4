"""How large a display pixel is as a visual angle, where it matters (docs/optics.md, "Pixel angles").

A display profile's image is a flat rectangle of tangents (psyop.optics.display), so its
pixels are equal steps of tangent, not of angle: seen from the eye's centre of rotation a pixel
on the axis subtends the most, one at the edge of a wide field much less (a factor
``1 / (1 + tan^2)`` across the edge, ``1 / sqrt(1 + tan^2)`` along it). The paper's single figure,
field of view over pixels (4.58 arcmin/px for the Vive Pro), is only the average across a row.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from psyop.optics.angles import angle_between_deg
from psyop.optics.display import DisplayProfile


@dataclass(frozen=True)
class PixelAngle:
    """One pixel's width and height as angles seen from the eye's centre of rotation (arcmin):
    the angle between the midpoints of its left and right sides, and of its top and bottom."""

    column: int
    row: int
    width_arcmin: float
    height_arcmin: float


@dataclass(frozen=True)
class PixelAngles:
    """A profile's pixel angles for one eye: the pixel on the straight-ahead axis (or the image
    centre when the axis is outside the image), the pixel at the middle of each edge (on the
    axis's row or column), and the average across a row (horizontal FOV / width)."""

    profile: str
    eye: str
    centre: PixelAngle
    left: PixelAngle
    right: PixelAngle
    top: PixelAngle
    bottom: PixelAngle
    average_width_arcmin: float

    def lines(self) -> list[str]:
        """Readable lines (``psyop show``)."""

        def fmt(name: str, p: PixelAngle) -> str:
            return (f"  {name:<7} pixel ({p.column}, {p.row}): {p.width_arcmin:.2f} x {p.height_arcmin:.2f} arcmin "
                    "(width x height)")

        return [f"display pixels ({self.profile}, {self.eye} eye; seen from the eye's centre of rotation):",
                fmt("centre", self.centre), fmt("left", self.left), fmt("right", self.right), fmt("top", self.top),
                fmt("bottom", self.bottom),
                f"  average across a row: {self.average_width_arcmin:.2f} arcmin (horizontal FOV / width; not any "
                "one pixel's size)"]


def pixel_angle(profile: DisplayProfile, column: int, row: int, eye: str = "right") -> PixelAngle:
    """Width and height (arcmin) of pixel (``column``, ``row``) (row 0 at the top) of ``eye``'s image.

    Examples
    --------
    >>> from psyop.optics.display import VIVE_PRO
    >>> round(pixel_angle(VIVE_PRO, 720, 800).width_arcmin, 2)
    6.82
    >>> round(pixel_angle(VIVE_PRO, 1439, 800).width_arcmin, 2)
    2.25
    """
    if not (0 <= column < profile.width_px and 0 <= row < profile.height_px):
        raise ValueError(f"pixel ({column}, {row}) is outside the {profile.width_px}x{profile.height_px} image")
    left, right, bottom, top = profile.frustum_tangents(eye)
    step_x = (right - left) / profile.width_px
    step_y = (top - bottom) / profile.height_px
    x0, x1 = left + column * step_x, left + (column + 1) * step_x
    y1, y0 = top - row * step_y, top - (row + 1) * step_y  # row 0 at the top
    xm, ym = (x0 + x1) / 2.0, (y0 + y1) / 2.0

    def ray(x: float, y: float) -> np.ndarray:
        return np.array([x, y, -1.0])

    width = float(angle_between_deg(ray(x0, ym), ray(x1, ym))) * 60.0
    height = float(angle_between_deg(ray(xm, y0), ray(xm, y1))) * 60.0
    return PixelAngle(column, row, width, height)


def pixel_angles(profile: DisplayProfile, eye: str = "right") -> PixelAngles:
    """The centre and edge pixel angles of ``profile`` for ``eye``.

    Examples
    --------
    >>> from psyop.optics.display import VIVE_PRO
    >>> facts = pixel_angles(VIVE_PRO)
    >>> round(facts.centre.width_arcmin, 2), round(facts.right.width_arcmin, 2), round(facts.average_width_arcmin, 2)
    (6.82, 2.25, 4.58)
    """
    left, right, bottom, top = profile.frustum_tangents(eye)
    w, h = profile.width_px, profile.height_px
    # the pixel containing the straight-ahead axis (tangent 0, 0), else the image centre
    column = math.floor(-left / (right - left) * w) if left < 0.0 < right else w // 2
    row = math.floor(top / (top - bottom) * h) if bottom < 0.0 < top else h // 2
    column, row = min(max(column, 0), w - 1), min(max(row, 0), h - 1)
    return PixelAngles(
        profile=profile.name, eye=str(eye),
        centre=pixel_angle(profile, column, row, eye),
        left=pixel_angle(profile, 0, row, eye), right=pixel_angle(profile, w - 1, row, eye),
        top=pixel_angle(profile, column, 0, eye), bottom=pixel_angle(profile, column, h - 1, eye),
        average_width_arcmin=profile.horizontal_fov_deg * 60.0 / w,
    )
