"""The one valid range of each configured optical quantity.

Protocol validation (``psyop.protocol``), the eye models, the eye rig and the camera all check
against these, so a value that validates never raises later in the camera (and one that the
camera would refuse is refused at validation, with the protocol file and line).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class ValidRange:
    """``low <= x < high`` (ends closed or open per the flags), finite; ``unit`` in SI."""

    name: str
    unit: str
    low: float
    high: float
    high_inclusive: bool = False
    low_inclusive: bool = True

    def contains(self, value: float) -> bool:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            return False
        above = self.low <= value if self.low_inclusive else self.low < value
        below = value <= self.high if self.high_inclusive else value < self.high
        return above and below

    def describe(self, scale: float = 1.0, unit: str | None = None) -> str:
        open_, close = "[" if self.low_inclusive else "(", "]" if self.high_inclusive else ")"
        return f"{open_}{self.low * scale:g}, {self.high * scale:g}{close} {unit or self.unit}"

    def check(self, value: float, what: str | None = None) -> float:
        """``value`` if it is in range, else ``ValueError`` naming the quantity and the range."""
        if not self.contains(value):
            raise ValueError(f"{what or self.name} must be in {self.describe()}, got {value!r}")
        return float(value)


#: Distance NC from the eye's centre of rotation to its front nodal point (schematic eyes:
#: 5.6-9.2 mm; 30 mm and more is a unit error).
NC_M = ValidRange("nc_m", "m", 0.0, 0.03, low_inclusive=False)
#: Inter-pupillary distance (adult range with margin: 5th-95th percentile is about 55-70 mm): the one bound of
#: every ipd psyop takes (protocol ``ipd: {mm: ...}``, the eye rig, ``psyop audit`` / ``psyop render --ipd-mm``).
IPD_M = ValidRange("ipd_m", "m", 0.040, 0.090, high_inclusive=True)
#: The ipd a session uses when neither the protocol nor the tracker gives one (and ``psyop audit`` / ``psyop
#: render`` for a protocol that takes it from the tracker), m.
DEFAULT_IPD_M = 0.063
#: A depth in dioptres: 0 = optical infinity, 100 D = 1 cm from the eye.
DEPTH_D = ValidRange("depth_D", "D", 0.0, 100.0, high_inclusive=True)
