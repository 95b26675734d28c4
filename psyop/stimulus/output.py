"""What the renderer's values mean: pixel values written as they are, or normalised luminance on a calibrated
display (docs/gratings_and_luminance.md).

Uncalibrated (:data:`PIXEL_OUTPUT`): every value a protocol gives (``rgb``, a pattern's ``mean``) is the pixel value
the display receives, unchanged: the float image is converted to 8 bits by rounding ``v * 255`` (no sRGB encoding,
no gamma), exactly as before calibrations existed.

Calibrated (:class:`Output` with a :class:`psyop.optics.transfer.DisplayTransfer`): the ray-cast works in normalised
luminance ``L / L_peak`` (L_peak: the calibration's grey luminance at code 255) and the renderer's final pass maps
it to codes through the calibration's inverse (:class:`psyop.rendering.scene.OutputTransfer`). Pixel values given
as ``rgb`` are turned into the luminance of their own code (``round(v * 255)``), so they still show that code.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import dataclasses

from psyop.errors import UserError
from psyop.optics.transfer import DisplayTransfer
from psyop.rendering.scene import Aperture, GridMaterial, Material, NoiseTexture, OutputTransfer, Primitive, Solid

#: entries of the renderer's table: the forward model every 1/64 of a code (every whole code is an entry)
TABLE_SIZE = MAX_CODE_STEPS = 255 * 64 + 1
_TABLES: dict[str, OutputTransfer] = {}

#: the codes of an 8-bit channel
MAX_CODE = 255


def pixel_code(value: float) -> int:
    """The 8-bit code a pixel value shows: ``floor(v * 255 + 0.5)`` (half codes up)."""
    return int(math.floor(min(max(float(value), 0.0), 1.0) * MAX_CODE + 0.5))


@dataclass(frozen=True)
class Output:
    """How protocol values become the renderer's values (see the module docstring). ``transfer``: the display's
    calibration (:class:`psyop.optics.transfer.DisplayTransfer`), None for pixel values."""

    transfer: DisplayTransfer | None = None

    @property
    def calibrated(self) -> bool:
        return self.transfer is not None

    def pixel_value(self, value: float) -> float:
        """A pixel value (0..1) as the renderer's value: itself, or the normalised luminance of its code."""
        if self.transfer is None:
            return float(value)
        return float(self.transfer.normalised(self.transfer.luminance_cd_m2(pixel_code(value))))

    def pixel_rgb(self, rgb: tuple[float, float, float]) -> tuple[float, float, float]:
        r, g, b = (self.pixel_value(c) for c in rgb)
        return (r, g, b)

    def luminance_value(self, cd_m2: float) -> float:
        """A luminance (cd/m²) as the renderer's value (normalised luminance); refused without a calibration."""
        if self.transfer is None:
            raise UserError("a luminance ({cd_m2: ...}) needs a calibrated display: add display: calibration: FILE "
                            "(psyop calibrate), or give the surface as pixel values (rgb, mean)")
        return float(self.transfer.normalised(float(cd_m2)))

    def scene_output(self) -> OutputTransfer | None:
        """The renderer's final pass for this display (None: values written as they are); one table per calibration."""
        if self.transfer is None:
            return None
        table = _TABLES.get(self.transfer.key)
        if table is None:
            _TABLES.clear()
            table = _TABLES[self.transfer.key] = OutputTransfer(self.transfer.forward_table(TABLE_SIZE),
                                                                key=self.transfer.key)
        return table

    def material(self, material: Material) -> Material:
        """A builder's material given in pixel values (a fixation target, grid lines, a room) as the renderer's
        values: each colour the luminance of its own code; a noise texture's mean likewise (its contrast is then
        a luminance contrast). Unchanged without a calibration."""
        if self.transfer is None:
            return material
        if isinstance(material, Solid):
            return Solid(self.pixel_rgb(material.colour))
        if isinstance(material, GridMaterial):
            return dataclasses.replace(material, background=self.pixel_rgb(material.background),
                                       line_colour=self.pixel_rgb(material.line_colour))
        if isinstance(material, NoiseTexture):
            return dataclasses.replace(material, mean=self.pixel_value(material.mean))
        return material

    def primitives(self, prims: list[Primitive]) -> list[Primitive]:
        """:meth:`material` of every primitive (the same objects without a calibration)."""
        if self.transfer is None:
            return prims
        return [dataclasses.replace(p, material=self.material(p.material)) for p in prims]

    def aperture(self, aperture: Aperture) -> Aperture:
        if self.transfer is None:
            return aperture
        return dataclasses.replace(aperture, colour=self.pixel_rgb(aperture.colour))

    @staticmethod
    def amplitude(mean: float, michelson: float) -> float:
        """A pattern's amplitude around ``mean`` for a Michelson contrast (linear values: (max - min) / (max + min))."""
        return float(mean) * float(michelson)


#: uncalibrated: values are pixel values, written as they are
PIXEL_OUTPUT = Output()
