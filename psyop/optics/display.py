"""Display profiles: per-eye resolution, refresh rate, frustum and virtual-image distance.

A head-mounted display shows each eye a virtual image: a rectangle fixed in head space at
distance ``d_m`` in front of that eye's centre of rotation C. Its extent is given as
tangents of the half-angles seen from C (OpenVR's ``GetProjectionRaw`` convention, with
bottom negative and top positive): x from ``d * tan_left`` to ``d * tan_right``, y from
``d * tan_bottom`` to ``d * tan_top``. The tangents are stored for the right eye; the left
eye is mirrored in x (left/right swap and change sign) unless ``left_tangents`` gives the left
eye's own (left, right, bottom, top): a headset's two frusta are rarely mirror images (an
OpenXR runtime reports each eye's field of view, psyop.devices.xr). ``d_m = inf`` (the paper's
choice) means the image is at optical infinity: only directions matter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import Mapping
from psyop.records import JsonMapping

#: Smallest allowed virtual-image distance. The centre of projection moves up to NC (< 1 cm)
#: from C, so the image must stay well in front of it for the frustum to be defined.
MIN_IMAGE_DISTANCE_M = 0.05


@dataclass(frozen=True)
class DisplayProfile:
    """One HMD's per-eye image geometry (see the module docstring for conventions)."""

    name: str
    width_px: int
    height_px: int
    refresh_hz: float
    tan_left: float
    tan_right: float
    tan_bottom: float
    tan_top: float
    d_m: float = math.inf
    #: the left eye's own (left, right, bottom, top) tangents; None: the right eye's, mirrored in x
    left_tangents: tuple[float, float, float, float] | None = None

    def __post_init__(self) -> None:
        problems = []
        if self.left_tangents is not None:
            lt = tuple(self.left_tangents)
            if len(lt) != 4 or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                       and math.isfinite(v) for v in lt):
                problems.append(f"left_tangents must be 4 finite numbers (left, right, bottom, top), got {self.left_tangents!r}")
            elif not (lt[0] < lt[1] and lt[2] < lt[3]):
                problems.append(f"left_tangents {lt}: need left < right and bottom < top")
            else:
                object.__setattr__(self, "left_tangents", tuple(float(v) for v in lt))
        for field in ("width_px", "height_px"):
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
                problems.append(f"{field} must be a positive integer, got {value!r}")
        for field in ("refresh_hz", "tan_left", "tan_right", "tan_bottom", "tan_top"):
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                problems.append(f"{field} must be a finite number, got {value!r}")
        if not problems:
            if self.refresh_hz <= 0:
                problems.append(f"refresh_hz must be positive, got {self.refresh_hz}")
            if not self.tan_left < self.tan_right:
                problems.append(f"tan_left ({self.tan_left}) must be less than tan_right ({self.tan_right})")
            if not self.tan_bottom < self.tan_top:
                problems.append(f"tan_bottom ({self.tan_bottom}) must be less than tan_top ({self.tan_top})")
        d = self.d_m
        if isinstance(d, bool) or not isinstance(d, (int, float)) or math.isnan(d) or not d >= MIN_IMAGE_DISTANCE_M:
            problems.append(f"d_m must be >= {MIN_IMAGE_DISTANCE_M} m or inf, got {d!r}")
        if problems:
            raise ValueError(f"display profile {self.name!r}: " + "; ".join(problems))

    def frustum_tangents(self, eye: str) -> tuple[float, float, float, float]:
        """(left, right, bottom, top) tangents seen from the eye's centre of rotation."""
        if str(eye) == "right":
            return (self.tan_left, self.tan_right, self.tan_bottom, self.tan_top)
        if str(eye) == "left":
            if self.left_tangents is not None:
                return self.left_tangents
            return (-self.tan_right, -self.tan_left, self.tan_bottom, self.tan_top)
        raise ValueError(f"eye must be 'left' or 'right', got {eye!r}")

    @property
    def horizontal_fov_deg(self) -> float:
        return math.degrees(math.atan(self.tan_right) - math.atan(self.tan_left))

    @property
    def vertical_fov_deg(self) -> float:
        return math.degrees(math.atan(self.tan_top) - math.atan(self.tan_bottom))

    @property
    def arcmin_per_px(self) -> float:
        """The paper's resolution measure: horizontal FOV / width (4.58 for the Vive Pro)."""
        return self.horizontal_fov_deg * 60.0 / self.width_px

    @property
    def frame_period_s(self) -> float:
        return 1.0 / self.refresh_hz


def symmetric_profile(
    name: str, width_px: int, height_px: int, refresh_hz: float, horizontal_fov_deg: float,
    vertical_fov_deg: float | None = None, d_m: float = math.inf,
) -> DisplayProfile:
    """A symmetric frustum from a horizontal FOV. Without ``vertical_fov_deg`` the vertical
    extent is aspect-matched: equal pixel pitch in tangent space (square pixels on the image)."""
    for key, value in (("horizontal_fov_deg", horizontal_fov_deg), ("vertical_fov_deg", vertical_fov_deg)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))):
            raise ValueError(f"display profile {name!r}: {key} must be a number, got {value!r}")
    if not 0.0 < horizontal_fov_deg < 180.0:
        raise ValueError(f"display profile {name!r}: horizontal_fov_deg must be in (0, 180), got {horizontal_fov_deg}")
    tx = math.tan(math.radians(horizontal_fov_deg) / 2.0)
    if vertical_fov_deg is None:
        ty = tx * height_px / width_px
    else:
        if not 0.0 < vertical_fov_deg < 180.0:
            raise ValueError(f"display profile {name!r}: vertical_fov_deg must be in (0, 180), got {vertical_fov_deg}")
        ty = math.tan(math.radians(vertical_fov_deg) / 2.0)
    return DisplayProfile(name, width_px, height_px, float(refresh_hz), -tx, tx, -ty, ty, d_m)


#: HTC Vive Pro as the paper describes it: 1440x1600 per eye, 90 Hz, 110 deg field of view,
#: image at optical infinity. No published per-eye raw projection (OpenVR GetProjectionRaw)
#: values for the Vive Pro could be verified, so the frustum is a symmetric 110 deg horizontal
#: field with the vertical extent aspect-matched (tan = tan(55 deg) * 1600/1440, about 115.6 deg).
#: This reproduces the paper's 110 deg / 1440 px = 4.58 arcmin/px exactly. Real headsets are
#: asymmetric (the original Vive reports about -1.39/+1.25 for the left eye); measure and supply
#: a user profile where the exact frustum matters.
VIVE_PRO: DisplayProfile = symmetric_profile("vive_pro", 1440, 1600, 90.0, 110.0)

DISPLAY_PROFILES: Mapping[str, DisplayProfile] = MappingProxyType({VIVE_PRO.name: VIVE_PRO})


def get_display_profile(name: str) -> DisplayProfile:
    """A built-in profile by name; ``ValueError`` listing the valid names otherwise."""
    try:
        return DISPLAY_PROFILES[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown display profile {name!r}; valid names: {', '.join(DISPLAY_PROFILES)}") from None


_TANGENT_KEYS = ("tan_left", "tan_right", "tan_bottom", "tan_top")
_ALLOWED_KEYS = {"name", "width_px", "height_px", "refresh_hz", "d_m", "horizontal_fov_deg", "vertical_fov_deg",
                 "left_tangents", *_TANGENT_KEYS}


def _parse_distance(value: object) -> float:
    if value is None:
        return math.inf
    if isinstance(value, str) and value.strip().lower() in ("inf", "infinity", ".inf"):
        return math.inf
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"d_m must be a number of metres or 'inf', got {value!r}")
    return float(value)


def display_profile_from_mapping(mapping: JsonMapping) -> DisplayProfile:
    """Validate a user-defined profile (e.g. read from protocol YAML) and build it.

    Required: ``name``, ``width_px``, ``height_px``, ``refresh_hz``, and either all four of
    ``tan_left, tan_right, tan_bottom, tan_top`` (right eye; optional ``left_tangents``: the left
    eye's own four, else mirrored) or ``horizontal_fov_deg``
    (symmetric; optional ``vertical_fov_deg``, else aspect-matched). Optional ``d_m``
    (metres, ``inf``/``null`` = optical infinity, the default). Raises ``ValueError`` naming
    every problem; the protocol layer adds file:line:column.
    """
    if not isinstance(mapping, Mapping):
        raise ValueError(f"display profile must be a mapping, got {type(mapping).__name__}")
    unknown = sorted(set(mapping) - _ALLOWED_KEYS)
    if unknown:
        raise ValueError(f"display profile: unknown key(s) {unknown}; allowed: {sorted(_ALLOWED_KEYS)}")
    missing = [k for k in ("name", "width_px", "height_px", "refresh_hz") if k not in mapping]
    has_tangents = [k for k in _TANGENT_KEYS if k in mapping]
    if has_tangents and len(has_tangents) != 4:
        missing += [k for k in _TANGENT_KEYS if k not in mapping]
    if not has_tangents and "horizontal_fov_deg" not in mapping:
        missing.append("horizontal_fov_deg (or tan_left/tan_right/tan_bottom/tan_top)")
    if has_tangents and ("horizontal_fov_deg" in mapping or "vertical_fov_deg" in mapping):
        raise ValueError("display profile: give either the four tangents or the fov_deg keys, not both")
    if missing:
        raise ValueError(f"display profile: missing key(s) {missing}")
    name = mapping["name"]
    if not isinstance(name, str) or not name:
        raise ValueError(f"display profile: name must be a non-empty string, got {name!r}")
    d_m = _parse_distance(mapping.get("d_m"))
    left = mapping.get("left_tangents")
    if left is not None and not has_tangents:
        raise ValueError("display profile: left_tangents needs the right eye's four tangents (tan_left, tan_right, "
                         "tan_bottom, tan_top), not horizontal_fov_deg")
    if left is not None and (not isinstance(left, (list, tuple)) or len(left) != 4):
        raise ValueError(f"display profile: left_tangents must be a list of 4 numbers [left, right, bottom, top], got {left!r}")
    if has_tangents:
        return DisplayProfile(name, mapping["width_px"], mapping["height_px"], mapping["refresh_hz"],
                              **{k: mapping[k] for k in _TANGENT_KEYS}, d_m=d_m,
                              left_tangents=None if left is None else tuple(left))
    for k in ("width_px", "height_px"):
        if isinstance(mapping[k], bool) or not isinstance(mapping[k], int) or mapping[k] <= 0:
            raise ValueError(f"display profile {name!r}: {k} must be a positive integer, got {mapping[k]!r}")
    return symmetric_profile(name, mapping["width_px"], mapping["height_px"], mapping["refresh_hz"],
                             mapping["horizontal_fov_deg"], mapping.get("vertical_fov_deg"), d_m)
