"""Display, eye-model and ipd sections of a protocol.

These stay plain names and numbers here (validated for sanity); ``psyop.optics`` turns them
into a ``DisplayProfile`` / ``EyeModel`` (see :func:`resolve_display_profile`,
:func:`resolve_eye_model`). The name lists mirror ``psyop.optics`` (a test checks that they agree).
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import Field, field_validator, model_validator

from psyop.optics.ranges import DEFAULT_IPD_M, IPD_M, NC_M
from psyop.protocol.base import Integer, Number, StrictModel
from psyop.protocol.scene import FactorRef

#: the most gaze latency a protocol may add (``display.added_latency_ms``), ms
MAX_ADDED_LATENCY_MS = 1000.0
#: Built-in display profiles (``psyop.optics.display.DISPLAY_PROFILES``).
DISPLAY_PROFILE_NAMES: tuple[str, ...] = ("vive_pro",)
#: Schematic eyes of the paper's Table 1 (``psyop.optics.eye_models.EYE_MODELS``).
EYE_MODEL_NAMES: tuple[str, ...] = (
    "gullstrand_no1_relaxed",
    "gullstrand_no1_accommodated",
    "gullstrand_emsley_relaxed",
    "gullstrand_emsley_accommodated",
    "emsley_reduced",
)


def _known(kind: str, names: tuple[str, ...]):
    def check(value: str) -> str:
        if value not in names:
            import difflib

            close = difflib.get_close_matches(value, names, n=1)
            hint = f" Did you mean '{close[0]}'?" if close else ""
            raise ValueError(f"unknown {kind} '{value}'.{hint} Known: {', '.join(names)}; or give an inline definition")
        return value

    return check


class InlineDisplayProfile(StrictModel):
    """A user display: per-eye pixels, refresh rate, and either a symmetric field of view or the
    four frustum tangents of the right eye (OpenVR ``GetProjectionRaw`` convention)."""

    name: str = Field(min_length=1)
    width_px: Integer = Field(gt=0, le=32768)
    height_px: Integer = Field(gt=0, le=32768)
    refresh_hz: Number = Field(gt=0, le=1000)
    horizontal_fov_deg: Number | None = Field(default=None, gt=0, lt=180)
    vertical_fov_deg: Number | None = Field(default=None, gt=0, lt=180)
    tan_left: Number | None = None
    tan_right: Number | None = None
    tan_bottom: Number | None = None
    tan_top: Number | None = None
    left_tangents: list[Number] | None = Field(
        default=None, min_length=4, max_length=4,
        description="the left eye's own [tan_left, tan_right, tan_bottom, tan_top]; default: the right eye's mirrored")
    d_m: Number | Literal["inf"] = Field(default="inf", description="virtual-image distance, metres, or 'inf'")

    @field_validator("d_m")
    @classmethod
    def _distance(cls, value: float | str) -> float | str:
        if isinstance(value, float) and value < 0.05:
            raise ValueError("the virtual image must be at least 0.05 m away (or 'inf', the paper's choice)")
        return value

    @model_validator(mode="after")
    def _extent(self) -> "InlineDisplayProfile":
        tangents = [self.tan_left, self.tan_right, self.tan_bottom, self.tan_top]
        given = [t is not None for t in tangents]
        if any(given) and not all(given):
            raise ValueError("give all four of tan_left, tan_right, tan_bottom, tan_top, or none")
        if all(given) and (self.horizontal_fov_deg is not None or self.vertical_fov_deg is not None):
            raise ValueError("give either the four tangents or horizontal_fov_deg, not both")
        if not all(given) and self.horizontal_fov_deg is None:
            raise ValueError("give horizontal_fov_deg (symmetric) or the four tangents tan_left/right/bottom/top")
        left, right, bottom, top = tangents
        if (left is not None and right is not None and bottom is not None and top is not None
                and not (left < right and bottom < top)):
            raise ValueError("tan_left must be < tan_right and tan_bottom < tan_top")
        if self.left_tangents is not None:
            if not all(given):
                raise ValueError("left_tangents needs the right eye's four tangents tan_left/right/bottom/top")
            lt = self.left_tangents
            if not (lt[0] < lt[1] and lt[2] < lt[3]):
                raise ValueError("left_tangents [left, right, bottom, top]: need left < right and bottom < top")
        return self

    @property
    def image_distance_m(self) -> float:
        return math.inf if self.d_m == "inf" else float(self.d_m)


class InlineEyeModel(StrictModel):
    """A calibrated eye: distance NC from the centre of rotation to the front nodal point."""

    nc_mm: Number = Field(gt=NC_M.low * 1000, lt=NC_M.high * 1000,
                          description="centre of rotation to front nodal point, mm (paper: 7.6916); "
                                      "range psyop.optics.ranges.NC_M")
    name: str = "user"


class FixedIpd(StrictModel):
    """Inter-pupillary distance fixed for the session, mm."""

    mm: Number = Field(ge=IPD_M.low * 1000, le=IPD_M.high * 1000, description="range psyop.optics.ranges.IPD_M")

    @property
    def ipd_m(self) -> float:
        return self.mm / 1000.0


def protocol_ipd_m(ipd: Literal["tracker"] | FixedIpd, fallback_m: float = DEFAULT_IPD_M) -> float:
    """The ipd (m) a protocol's ``display.ipd`` gives: its fixed one, else ``fallback_m`` (the tracker's where
    known, else the sessions' default psyop.optics.ranges.DEFAULT_IPD_M)."""
    return ipd.ipd_m if isinstance(ipd, FixedIpd) else float(fallback_m)


class RenderingNc(StrictModel):
    """The NC the renderer uses in ocular and reversed modes, instead of the eye model's: ``mm`` (a
    number or ``{factor: NAME}``, NAME ending in ``_mm``) or ``scale`` (a multiple of the eye model's
    NC; a number or ``{factor: NAME}``). Give one. Every value must give an NC in psyop.optics.ranges.NC_M.
    ``signed: true`` (a factor, with a ``with_against`` response): the level's sign picks the trial's mode
    (> 0 ocular, 0 conventional, < 0 reversed) and its size the NC."""

    mm: Number | FactorRef | None = None
    scale: Number | FactorRef | None = None
    signed: bool = False

    @model_validator(mode="after")
    def _one(self) -> "RenderingNc":
        if (self.mm is None) == (self.scale is None):
            raise ValueError("give one of mm (the rendered NC in mm) or scale (a multiple of the eye model's NC)")
        return self


class DisplaySpec(StrictModel):
    """Which headset, which schematic eye and where the ipd comes from."""

    profile: Annotated[str, Field(description="built-in profile name")] | InlineDisplayProfile = "vive_pro"
    eye_model: str | InlineEyeModel = "gullstrand_emsley_relaxed"
    ipd: Literal["tracker"] | FixedIpd = "tracker"
    rendering_nc: RenderingNc | None = None
    calibration: str | None = Field(
        default=None, min_length=1,
        description="the display's calibration file (psyop calibrate --out FILE), relative to the protocol: surfaces "
                    "may then state luminance: {cd_m2: ...} and the renderer linearises its output "
                    "(docs/gratings_and_luminance.md; read and checked by psyop.protocol.luminance)")
    added_latency_ms: Number | FactorRef | None = Field(
        default=None,
        description="gaze latency added on purpose, ms (0..1000), or {factor: NAME} (NAME ending in _ms): each frame "
                    "is rendered with the gaze sample this much older than the newest one (docs/latency.md)")

    @field_validator("added_latency_ms", mode="after")
    @classmethod
    def _latency(cls, value: Any) -> Any:  # Any: pydantic validator input
        if isinstance(value, float) and not 0.0 <= value <= MAX_ADDED_LATENCY_MS:
            raise ValueError(f"added_latency_ms must be in [0, {MAX_ADDED_LATENCY_MS:g}] ms")
        return value

    @field_validator("profile", mode="after")
    @classmethod
    def _profile_name(cls, value: Any) -> Any:  # Any: pydantic validator input
        return _known("display profile", DISPLAY_PROFILE_NAMES)(value) if isinstance(value, str) else value

    @field_validator("eye_model", mode="after")
    @classmethod
    def _eye_name(cls, value: Any) -> Any:  # Any: pydantic validator input
        return _known("eye model", EYE_MODEL_NAMES)(value) if isinstance(value, str) else value


def resolve_display_profile(spec: DisplaySpec):
    """The ``psyop.optics.DisplayProfile`` for this protocol (imports optics lazily)."""
    from psyop.optics.display import display_profile_from_mapping, get_display_profile

    if isinstance(spec.profile, str):
        return get_display_profile(spec.profile)
    data = spec.profile.model_dump(exclude_none=True)
    data["d_m"] = spec.profile.image_distance_m
    return display_profile_from_mapping(data)


def rendering_nc_rule(spec: DisplaySpec):
    """The ``psyop.optics.rig.NcRule`` of ``display.rendering_nc``, or None (render with the eye model's NC)."""
    from psyop.optics.rig import NcRule

    nc = spec.rendering_nc
    if nc is None:
        return None
    if isinstance(nc.mm, FactorRef):
        return NcRule(column=nc.mm.factor, column_unit="mm", signed=nc.signed)
    if isinstance(nc.scale, FactorRef):
        return NcRule(column=nc.scale.factor, column_unit="scale", signed=nc.signed)
    if nc.mm is not None:
        return NcRule(nc_m=float(nc.mm) / 1000.0)
    assert nc.scale is not None  # RenderingNc._one: exactly one of mm and scale is given
    return NcRule(scale=float(nc.scale))


def resolve_eye_model(spec: DisplaySpec):
    """The ``psyop.optics.EyeModel`` for this protocol (imports optics lazily)."""
    from psyop.optics.eye_models import get_eye_model, user_eye_model

    if isinstance(spec.eye_model, str):
        return get_eye_model(spec.eye_model)
    return user_eye_model(spec.eye_model.nc_mm / 1000.0, spec.eye_model.name)
