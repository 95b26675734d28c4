"""Schematic eye models of the paper's Table 1 and the centre-of-rotation distance NC.

Table 1 lists the front and rear nodal points (VN, VN') in mm behind the anterior vertex of
the cornea V. Fry & Hill (1962) put the centre of rotation C 14.7536 mm behind the cornea, so
the distance from C forward to the front nodal point N is ``NC = 14.7536 - VN``. The paper
uses the relaxed Gullstrand-Emsley eye: NC = 14.7536 - 7.062 = 7.6916 mm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import Mapping

#: Fry & Hill (1962): mean distance from the anterior cornea to the centre of rotation.
CENTRE_OF_ROTATION_MM = 14.7536


@dataclass(frozen=True)
class EyeModel:
    """A schematic eye reduced to what ocular parallax needs.

    ``vn_mm`` / ``vn_prime_mm``: front / rear nodal point behind the cornea (mm).
    ``vc_mm``: centre of rotation behind the cornea (mm). ``nc_m`` is the distance from the
    centre of rotation forward to the front nodal point, the centre of projection.
    """

    name: str
    vn_mm: float
    vn_prime_mm: float
    vc_mm: float = CENTRE_OF_ROTATION_MM
    description: str = ""

    def __post_init__(self) -> None:
        for field in ("vn_mm", "vn_prime_mm", "vc_mm"):
            value = getattr(self, field)
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise ValueError(f"eye model {self.name!r}: {field} must be a finite number, got {value!r}")
        if not self.vc_mm > self.vn_mm:
            raise ValueError(
                f"eye model {self.name!r}: the nodal point (VN = {self.vn_mm} mm) must lie in front of "
                f"the centre of rotation (VC = {self.vc_mm} mm)"
            )

    @property
    def nc_mm(self) -> float:
        """Distance from the centre of rotation to the front nodal point, mm."""
        return self.vc_mm - self.vn_mm

    @property
    def nc_m(self) -> float:
        """Distance from the centre of rotation to the front nodal point, metres."""
        return self.nc_mm / 1000.0


def _table1() -> dict[str, EyeModel]:
    rows = [
        ("gullstrand_no1_relaxed", 7.078, 7.331, "Gullstrand No. 1, relaxed"),
        ("gullstrand_no1_accommodated", 6.533, 6.847, "Gullstrand No. 1, accommodated"),
        ("gullstrand_emsley_relaxed", 7.062, 7.363, "Gullstrand-Emsley, relaxed (paper default)"),
        ("gullstrand_emsley_accommodated", 6.562, 6.909, "Gullstrand-Emsley, accommodated"),
        ("emsley_reduced", 5.556, 5.556, "Emsley reduced eye"),
    ]
    return {name: EyeModel(name, vn, vnp, description=desc) for name, vn, vnp, desc in rows}


#: Every column of the paper's Table 1, by snake_case name (read-only).
EYE_MODELS: Mapping[str, EyeModel] = MappingProxyType(_table1())

#: The model the paper uses for all experiments.
DEFAULT_EYE_MODEL: EyeModel = EYE_MODELS["gullstrand_emsley_relaxed"]


def eye_model_names() -> tuple[str, ...]:
    """The valid names for :func:`get_eye_model`."""
    return tuple(EYE_MODELS)


def get_eye_model(name: str) -> EyeModel:
    """Look up a Table 1 model by name; ``ValueError`` listing the valid names otherwise."""
    try:
        return EYE_MODELS[name]
    except (KeyError, TypeError):
        valid = ", ".join(EYE_MODELS)
        raise ValueError(f"unknown eye model {name!r}; valid names: {valid}") from None


def user_eye_model(nc_m: float, name: str = "user") -> EyeModel:
    """A model with a calibrated NC (metres) for one participant.

    VN is derived as ``VC - NC`` with the Fry & Hill centre of rotation, so ``nc_m`` round-trips
    exactly in mm. NC must be in psyop.optics.ranges.NC_M ((0, 30) mm); a larger value is almost certainly a unit error.
    """
    from psyop.optics.ranges import NC_M

    NC_M.check(nc_m, f"user eye model {name!r}: nc_m")
    vn_mm = CENTRE_OF_ROTATION_MM - nc_m * 1000.0
    return EyeModel(name, vn_mm, vn_mm, description=f"user-calibrated, NC = {nc_m * 1000.0:.4f} mm")
