"""Scene primitives of a protocol: what is drawn, in degrees of visual angle and explicit depths.

Every primitive has an ``id`` (phases refer to it in ``show:``) and a ``kind`` (the
discriminator). Positions and sizes are visual angles seen from the scene origin (the eye's
centre of rotation, or the head origin in stereo): centres as Fick angles or eccentricity and
meridian, sizes as docs/optics.md ("Angles", "Sizes") defines them, at any depth. Depths carry their unit: ``{D: 2}`` (dioptres,
0 = optical infinity), ``{m: 0.5}``, or a reference to factor columns of the trial schedule.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Annotated, Any, Literal, Union

from pydantic import Field, model_validator

from psyop.optics.ranges import DEPTH_D
from psyop.protocol.base import Integer, Number, StrictModel

RenderingMode = Literal["conventional", "ocular", "reversed"]
RENDERING_MODES: tuple[str, ...] = ("conventional", "ocular", "reversed")


def _bare_number(value: object) -> float | None:
    """``1``, ``1.5`` or the text ``"1"``: a depth written without its unit (None: anything else)."""
    if isinstance(value, bool):
        return None
    if isinstance(value, (int, float)):
        return float(value)
    if isinstance(value, str):
        try:
            number = float(value)
        except ValueError:
            return None
        return number if math.isfinite(number) else None
    return None


#: keys people write for a depth's unit, and the one psyop reads (``{d: 2}``, ``{metres: 0.5}``, ``{cm: 50}``)
_UNIT_KEYS = {"d": "D", "dioptre": "D", "dioptres": "D", "diopter": "D", "diopters": "D", "dpt": "D",
              "M": "m", "metre": "m", "metres": "m", "meter": "m", "meters": "m"}
_SUBMETRE = {"cm": 100.0, "mm": 1000.0}


def _unit_key_hint(key: str, amount: object) -> str | None:
    number = _bare_number(amount)
    shown = f"{number:g}" if number is not None else "..."
    if key in _UNIT_KEYS:
        return f"write {{{_UNIT_KEYS[key]}: {shown}}}"
    if key in _SUBMETRE:
        metres = f"{number / _SUBMETRE[key]:g}" if number is not None else "..."
        return f"write it in metres, {{m: {metres}}}, or in dioptres (D)"
    return None


class Depth(StrictModel):
    """A distance from the eyes with an explicit unit.

    ``{D: 2}``: 2 dioptres (0.5 m). ``{m: 0.5}``: 0.5 m. ``{factor: back_D}``: the trial's value
    of factor ``back_D`` (dioptres when the name ends in ``_D``, metres when in ``_m``).
    ``{D: 0.5, factor: separation_D}`` or ``{factor: [back_D, level_D]}``: the sum, in dioptres.
    """

    D: Number | None = Field(default=None, ge=DEPTH_D.low, le=DEPTH_D.high,
                             description="dioptres (1/m); 0 = optical infinity; range psyop.optics.ranges.DEPTH_D")
    m: Number | None = Field(default=None, ge=1.0 / DEPTH_D.high, description="metres (at least 1 / the largest depth in D)")
    factor: str | list[str] | None = Field(default=None, description="factor column(s) to add, by name")

    @model_validator(mode="before")
    @classmethod
    def _a_unit_is_given(cls, value: Any) -> Any:  # Any: pydantic validator input
        number = _bare_number(value)
        if number is not None:
            raise ValueError(f"a depth needs its unit: write {{D: {number:g}}} (dioptres) or {{m: {number:g}}} (metres)")
        if isinstance(value, Mapping):
            for key, amount in value.items():
                hint = _unit_key_hint(str(key), amount)
                if hint:
                    raise ValueError(f"'{key}' is not a depth unit; {hint}")
        elif not isinstance(value, Depth):
            raise ValueError("a depth is a mapping with its unit: write {D: 2} (dioptres), {m: 0.5} (metres) or "
                             "{factor: NAME}")
        return value

    @model_validator(mode="after")
    def _one_unit(self) -> "Depth":
        if self.D is not None and self.m is not None:
            raise ValueError("give the depth either in dioptres (D) or in metres (m), not both")
        if self.D is None and self.m is None and self.factor is None:
            raise ValueError("give a depth: {D: 2}, {m: 0.5} or {factor: NAME}")
        if self.m is not None and self.factor is not None:
            raise ValueError("a metric depth cannot be added to a factor; use D with dioptre factors")
        if isinstance(self.factor, list) and not self.factor:
            raise ValueError("factor list is empty")
        return self

    @property
    def factor_names(self) -> tuple[str, ...]:
        if self.factor is None:
            return ()
        return (self.factor,) if isinstance(self.factor, str) else tuple(self.factor)

    def resolve_D(self, row: Mapping[str, float]) -> float:
        """The depth in dioptres for one trial (``row`` maps factor names to values)."""
        if self.m is not None:
            return 1.0 / self.m
        names = self.factor_names
        if len(names) == 1 and names[0].endswith("_m"):
            return 1.0 / float(row[names[0]])
        return float(self.D or 0.0) + sum(float(row[name]) for name in names)

    def constant_D(self) -> float | None:
        """The depth in dioptres when it does not depend on factors, else None."""
        return None if self.factor is not None else self.resolve_D({})


# ---- surfaces -------------------------------------------------------------------------------

Rgb = tuple[Annotated[Number, Field(ge=0, le=1)], Annotated[Number, Field(ge=0, le=1)],
            Annotated[Number, Field(ge=0, le=1)]]


class FactorRef(StrictModel):
    """A value read from the trial schedule's factor column: ``{factor: NAME}`` (the factor's levels
    must fit the field's range; validation checks each level, psyop.protocol.factor_fields)."""

    factor: str


#: A number, or ``{factor: NAME}``: the trial's level of a numeric factor (a size, a contrast).
Factorable = Union[Number, FactorRef]


#: a pattern's mean pixel value when neither ``mean`` nor ``luminance`` is given
PATTERN_MEAN = 0.5


def _mean_or_luminance(surface: StrictModel) -> None:
    """A pattern's mean is a pixel value (``mean``) or a luminance (``luminance``), not both."""
    if getattr(surface, "mean", None) is not None and getattr(surface, "luminance", None) is not None:
        raise ValueError("give the mean as mean (a pixel value) or as luminance: {cd_m2: ...}, not both")


class Luminance(StrictModel):
    """A luminance in cd/m² (``{cd_m2: 40}``, or ``{cd_m2: {factor: NAME}}``, NAME ending in ``_cd_m2``): only on a
    display with a calibration (``display: calibration: FILE``); validation refuses it elsewhere, and any value
    outside the calibrated range (docs/gratings_and_luminance.md)."""

    cd_m2: Annotated[Number, Field(gt=0, le=1e5)] | FactorRef


class SolidSurface(StrictModel):
    """A uniform colour: ``rgb``, pixel values in [0, 1] (written to the display as they are), or
    ``luminance: {cd_m2: 40}`` (a grey of that luminance, on a calibrated display). Give one."""

    kind: Literal["solid"]
    rgb: Rgb | None = None
    luminance: Luminance | None = None

    @model_validator(mode="after")
    def _one_colour(self) -> "SolidSurface":
        if (self.rgb is None) == (self.luminance is None):
            raise ValueError("give the colour as rgb: [r, g, b] (pixel values) or luminance: {cd_m2: ...} "
                             "(a calibrated display), one of them")
        return self


class WhiteNoiseSurface(StrictModel):
    """Binary-free grey-level white noise with square grains of ``grain_deg``."""

    kind: Literal["white_noise"]
    grain_deg: Number = Field(default=0.05, gt=0, le=10)
    mean: Annotated[Number, Field(ge=0, le=1)] | FactorRef | None = Field(
        default=None, description="grey level (pixel value); default 0.5 (PATTERN_MEAN) unless luminance is given")
    luminance: Luminance | None = Field(
        default=None, description="the mean as a luminance (calibrated display), instead of mean")
    contrast: Annotated[Number, Field(ge=0, le=1)] | FactorRef = Field(
        default=1.0, description="RMS-free peak contrast around the mean; a number or {factor: NAME}")
    seed: Integer = Field(default=0, ge=0, description="added to the trial seed, so two surfaces differ")

    @model_validator(mode="after")
    def _one_mean(self) -> "WhiteNoiseSurface":
        _mean_or_luminance(self)
        return self


class PinkNoiseSurface(StrictModel):
    """1/f^exponent amplitude-spectrum noise (``exponent: 1`` is 1/f)."""

    kind: Literal["one_over_f"]
    exponent: Number = Field(default=1.0, ge=0, le=4)
    mean: Annotated[Number, Field(ge=0, le=1)] | FactorRef | None = Field(
        default=None, description="grey level (pixel value); default 0.5 (PATTERN_MEAN) unless luminance is given")
    luminance: Luminance | None = Field(
        default=None, description="the mean as a luminance (calibrated display), instead of mean")
    contrast: Annotated[Number, Field(ge=0, le=1)] | FactorRef = Field(
        default=1.0, description="peak contrast around the mean; a number or {factor: NAME}")
    seed: Integer = Field(default=0, ge=0)

    @model_validator(mode="after")
    def _one_mean(self) -> "PinkNoiseSurface":
        _mean_or_luminance(self)
        return self


class ImageSurface(StrictModel):
    """An image file, path relative to the protocol file; it must exist."""

    kind: Literal["image"]
    path: str = Field(min_length=1)
    tile_deg: Number | None = Field(default=None, gt=0, description="repeat every tile_deg; default: stretch")


UnitFraction = Annotated[Number, Field(ge=0, le=1)]


class GaussianWindow(StrictModel):
    """A Gabor's envelope: ``exp(-r² / (2 sigma_deg²))``, r the surface-degree distance from the surface's centre."""

    kind: Literal["gaussian"]
    sigma_deg: Annotated[Number, Field(gt=0, lt=90)] | FactorRef


class RaisedCosineWindow(StrictModel):
    """A flat top of radius ``plateau_radius_deg`` (surface degrees from the centre), then a half cosine falling from 1
    to 0 over ``ramp_deg``: ``0.5 (1 + cos(pi (r - plateau) / ramp))``; 0 beyond ``plateau + ramp``."""

    kind: Literal["raised_cosine"]
    plateau_radius_deg: Annotated[Number, Field(ge=0, lt=90)] | FactorRef = 0.0
    ramp_deg: Annotated[Number, Field(gt=0, lt=90)] | FactorRef


Window = Annotated[Union[GaussianWindow, RaisedCosineWindow], Field(discriminator="kind")]


#: The lowest log10 Michelson contrast a protocol may state (1e-9: below what the renderer's float32 shading resolves)
MIN_MICHELSON_LOG10 = -9.0


class Contrast(StrictModel):
    """A contrast named by its definition: ``{michelson: 0.01}`` ((Lmax - Lmin) / (Lmax + Lmin)), ``{weber: 0.01}``
    ((Lmax - Lmean) / Lmean, the peak increment over the mean) or ``{michelson_log10: -2}`` (log10 of the Michelson
    contrast: an adaptive procedure's level on a log axis IS the contrast shown, 10 ** level). For a grating (sine or
    square, symmetric about its mean) Michelson and Weber are the same number; each may be ``{factor: NAME}`` (for
    ``michelson_log10`` a factor in log10 units, its name ending in ``_log10``). Give one."""

    michelson: UnitFraction | FactorRef | None = None
    weber: UnitFraction | FactorRef | None = None
    michelson_log10: Annotated[Number, Field(ge=MIN_MICHELSON_LOG10, le=0)] | FactorRef | None = None

    @model_validator(mode="after")
    def _one(self) -> "Contrast":
        if sum(v is not None for v in (self.michelson, self.weber, self.michelson_log10)) != 1:
            raise ValueError("give one of michelson, weber or michelson_log10")
        return self

    @property
    def linear(self) -> float | FactorRef:
        """The Michelson contrast as a fraction (``10 ** michelson_log10``); a factor reference as given (a log10
        factor's reference stays one: it is a number only once the trial's level is resolved)."""
        log10 = self.michelson_log10
        if log10 is not None:
            return log10 if isinstance(log10, FactorRef) else 10.0 ** float(log10)
        value = self.michelson if self.michelson is not None else self.weber
        assert value is not None
        return value


class GratingSurface(StrictModel):
    """A grating drawn procedurally (docs/gratings_and_luminance.md): ``L = mean (1 + contrast * window * s(2 pi
    cycles_per_deg x + phase))``, s = sin (``waveform: sine``) or its sign (``square``, box-filtered over each pixel),
    x the surface-degree coordinate along the modulation direction (``orientation_deg`` 0: vertical bars, modulation
    along the surface's right axis; positive angles turn the bars counter-clockwise). Surface degrees: metres on the
    surface along its own axes times 180 / (pi R), R the distance of its centre from the scene origin.
    ``drift_deg_s``: the bars move at that many surface degrees per second towards +x (the phase falls by
    360 cycles_per_deg drift_deg_s degrees per second). ``mean`` is a pixel value (0..1) or ``luminance: {cd_m2}``
    (a calibrated display); ``contrast`` Michelson (a number, ``{factor: NAME}``, ``{michelson: ...}`` or
    ``{weber: ...}``)."""

    kind: Literal["grating"]
    waveform: Literal["sine", "square"] = "sine"
    cycles_per_deg: Annotated[Number, Field(gt=0, le=60)] | FactorRef
    orientation_deg: Annotated[Number, Field(ge=-360, le=360)] | FactorRef = 0.0
    phase_deg: Annotated[Number, Field(ge=-360, le=360)] | FactorRef = 0.0
    drift_deg_s: Annotated[Number, Field(ge=-1000, le=1000)] | FactorRef | None = None
    mean: UnitFraction | FactorRef | None = Field(
        default=None, description="mean pixel value; default 0.5 (PATTERN_MEAN) unless luminance is given")
    luminance: Luminance | None = Field(default=None, description="the mean as a luminance (calibrated display)")
    contrast: UnitFraction | FactorRef | Contrast = Field(default=1.0, description="Michelson contrast")
    window: Window | None = None

    @model_validator(mode="after")
    def _one_mean(self) -> "GratingSurface":
        _mean_or_luminance(self)
        return self

    @property
    def michelson(self) -> float | FactorRef:
        """The Michelson contrast (Weber, as defined on :class:`Contrast`, is the same for these waveforms)."""
        c = self.contrast
        return c.linear if isinstance(c, Contrast) else c


Surface = Annotated[Union[SolidSurface, WhiteNoiseSurface, PinkNoiseSurface, ImageSurface, GratingSurface],
                    Field(discriminator="kind")]


# ---- primitives -----------------------------------------------------------------------------

#: A direction as Fick angles [azimuth_deg, elevation_deg] seen from the scene origin (docs/optics.md, "Angles"):
#: azimuth right-positive about the vertical axis, then elevation up-positive.
Point2Deg = tuple[Annotated[Number, Field(gt=-90, lt=90)], Annotated[Number, Field(gt=-90, lt=90)]]


class PolarPoint(StrictModel):
    """A direction in the polar form (docs/optics.md, "Angles"): ``eccentricity_deg`` from straight
    ahead, ``meridian_deg`` counter-clockwise from the right (0 right, 90 up, as the viewer sees it).
    Either may be ``{factor: NAME}`` (a factor in deg; every level must fit the field's range)."""

    eccentricity_deg: Annotated[Number, Field(ge=0, lt=90)] | FactorRef
    meridian_deg: Annotated[Number, Field(ge=-360, le=360)] | FactorRef


#: A primitive's centre [azimuth_deg, elevation_deg] whose angles may each be ``{factor: NAME}`` (a factor in deg).
FactorPoint2Deg = tuple[Annotated[Number, Field(gt=-90, lt=90)] | FactorRef,
                        Annotated[Number, Field(gt=-90, lt=90)] | FactorRef]

#: Where a primitive's centre lies: Fick angles ``[az, el]`` (each a number or a factor) or
#: ``{eccentricity_deg, meridian_deg}``.
Centre = Union[FactorPoint2Deg, PolarPoint]


def centre_eccentricity_deg(centre: "Centre") -> float:
    """Angle of a centre from straight ahead: ``acos(cos az cos el)`` for Fick angles (docs/optics.md);
    NaN while an angle is a factor (known per trial, once the factor's level is filled in)."""
    if isinstance(centre, PolarPoint):
        return math.nan if isinstance(centre.eccentricity_deg, FactorRef) else float(centre.eccentricity_deg)
    numbers = [c for c in centre if not isinstance(c, FactorRef)]
    if len(numbers) != len(centre):
        return math.nan
    az, el = (math.radians(float(c)) for c in numbers)
    return math.degrees(math.acos(max(-1.0, min(1.0, math.cos(az) * math.cos(el)))))


#: How a primitive is oriented (docs/optics.md, "Sizes"): in a frontoparallel plane (the paper's stimuli),
#: or facing the scene origin, so that it subtends its size in every direction.
Facing = Literal["frontoparallel", "eye"]


class _Primitive(StrictModel):
    id: str = Field(min_length=1, pattern=r"^[A-Za-z_][A-Za-z0-9_]*$", description="name used by phases' show:")


class Disc(_Primitive):
    """A disc of ``size_deg`` (diameter) at its depth (docs/optics.md, "Sizes"): frontoparallel, its
    diameter across the meridian through its centre subtends ``size_deg``; ``facing: eye``, it
    subtends ``size_deg`` in every direction. ``size_deg`` may be ``{factor: NAME}`` (a factor in deg)."""

    kind: Literal["disc"]
    size_deg: Annotated[Number, Field(gt=0, lt=180)] | FactorRef
    depth: Depth
    surface: Surface
    centre_deg: Centre = (0.0, 0.0)
    facing: Facing = "frontoparallel"


class Quad(_Primitive):
    """A rectangle ``width_deg`` x ``height_deg`` at its depth (each may be ``{factor: NAME}``), sized
    like a disc (docs/optics.md, "Sizes"): frontoparallel (axes along x and y) or ``facing: eye`` (axes
    along the centre's local right and up)."""

    kind: Literal["quad"]
    width_deg: Annotated[Number, Field(gt=0, lt=180)] | FactorRef
    height_deg: Annotated[Number, Field(gt=0, lt=180)] | FactorRef
    depth: Depth
    surface: Surface
    centre_deg: Centre = (0.0, 0.0)
    facing: Facing = "frontoparallel"


class SinusoidalBorder(_Primitive):
    """Two frontoparallel surfaces meeting along a sinusoidal border (the ordinal-depth stimulus).

    ``orientation_deg: 0`` is a vertical border with a ``left`` and a ``right`` surface; positive
    angles rotate it counter-clockwise. The nearer side is read from the schedule's
    ``near_side`` column (``near_side: schedule``) or fixed. The far surface extends behind the
    near one; both are scaled to subtend ``size_deg`` at their depth.
    """

    kind: Literal["sinusoidal_border"]
    size_deg: Number = Field(gt=0, lt=180, description="square extent of each surface")
    amplitude_deg: Number = Field(ge=0, lt=90)
    period_deg: Number = Field(gt=0, lt=360)
    orientation_deg: Number = Field(default=0.0, ge=-180, le=180)
    phase: Literal["random"] | Number = "random"
    left: Surface
    right: Surface
    near_depth: Depth
    far_depth: Depth
    near_side: Literal["schedule", "left", "right"] = "schedule"


class Aperture(_Primitive):
    """A circular window fixed to the eye's line of sight from the centre of rotation: it is
    never shifted by ocular parallax (``ignores_ocular_parallax`` is always true)."""

    kind: Literal["aperture"]
    diameter_deg: Number = Field(gt=0, lt=180)
    surround_rgb: Rgb = (0.0, 0.0, 0.0)
    ignores_ocular_parallax: Literal[True] = True


class GridPlanes(_Primitive):
    """Grid-lined planes (floor, ceiling, walls) forming a corridor that recedes from the viewer."""

    kind: Literal["grid_planes"]
    planes: list[Literal["floor", "ceiling", "left", "right"]] = Field(min_length=1)
    half_width_m: Number = Field(gt=0)
    half_height_m: Number = Field(gt=0)
    near_m: Number = Field(default=0.1, gt=0)
    far_m: Number = Field(default=20.0, gt=0)
    spacing_m: Number = Field(gt=0)
    line_width_deg: Number = Field(default=0.1, gt=0, lt=10)
    rgb: Rgb = (1.0, 1.0, 1.0)
    background_rgb: Rgb = (0.0, 0.0, 0.0)


class TargetField(_Primitive):
    """``count`` frontoparallel discs of ``size_deg``, placed at random (per trial, from the trial
    seed) within a circular field of ``field_deg`` so that none overlaps another in the
    conventional view, each at a depth drawn uniformly in dioptres between ``far`` and ``near``."""

    kind: Literal["target_field"]
    count: Integer = Field(ge=1, le=10000)
    size_deg: Number = Field(gt=0, lt=180)
    near: Depth
    far: Depth
    field_deg: Number = Field(gt=0, lt=180)
    min_gap_deg: Number = Field(default=0.0, ge=0)
    surface: Surface


class CirclePath(StrictModel):
    """A circle of constant ``eccentricity_deg`` around the target's ``centre_deg``, whose polar angle
    turns at the constant ``speed_deg_s`` (docs/optics.md, "Angles"; the target's own angular speed
    is ``speed_deg_s * sin(eccentricity_deg)``: 24.81 deg/s for 16 deg and 90 deg/s). Either may be
    ``{factor: NAME}`` (a factor in deg or deg/s): the drawn target and the simulated pursuit both take
    the trial's level. ``start: random`` / ``direction: random`` are drawn per trial and written to the schedule."""

    kind: Literal["circle"]
    eccentricity_deg: Annotated[Number, Field(gt=0, lt=90)] | FactorRef
    speed_deg_s: Annotated[Number, Field(gt=0, le=3600)] | FactorRef
    start: Literal["random"] | Annotated[Number, Field(ge=0, lt=360)] = "random"
    direction: Literal["random", "clockwise", "counterclockwise"] = "random"


class FixationTarget(_Primitive):
    """A small two-colour fixation target (a disc, sized as :class:`Disc`); static at ``centre_deg``
    or moving along ``path`` around it."""

    kind: Literal["fixation_target"]
    size_deg: Number = Field(gt=0, le=10)
    depth: Depth
    rgb: Rgb = (1.0, 0.0, 0.0)
    centre_rgb: Rgb = (1.0, 1.0, 1.0)
    centre_deg: Centre = (0.0, 0.0)
    facing: Facing = "frontoparallel"
    path: CirclePath | None = None


class Room(_Primitive):
    """A simple furnished room (floor, walls, a table) around the viewer, in metres."""

    kind: Literal["room"]
    width_m: Number = Field(gt=0, le=100)
    depth_m: Number = Field(gt=0, le=100)
    height_m: Number = Field(gt=0, le=20)
    table_height_m: Number | None = Field(default=None, gt=0)
    eye_height_m: Number = Field(default=1.2, gt=0, description="seated eye height above the floor")


class LevelRef(StrictModel):
    """``{factor: NAME}`` on a word field (a mesh's ``file`` or ``node``): the trial's level of a factor whose
    levels are words (file names, node names), so a categorical factor picks which model a trial shows.
    Kept apart from :class:`FactorRef` (numbers): the numeric resolution (psyop.protocol.factor_fields)
    leaves it alone and :meth:`Mesh.model_for` fills it in."""

    factor: str


#: A word, or ``{factor: NAME}``: a mesh's file or node, fixed or the trial's level of a word factor.
FactorWord = Union[Annotated[str, Field(min_length=1)], LevelRef]


def _word_factors(file: str | LevelRef, node: str | LevelRef | None) -> tuple[tuple[str, str], ...]:
    return tuple((name, ref.factor) for name, ref in (("file", file), ("node", node)) if isinstance(ref, LevelRef))


def _model_for(file: str | LevelRef, node: str | LevelRef | None,
               values: Mapping[str, object]) -> tuple[str, str | None]:
    def word(value: str | LevelRef | None) -> str | None:
        if not isinstance(value, LevelRef):
            return value
        level = values.get(value.factor)
        if not isinstance(level, str) or not level:
            raise ValueError(f"factor {value.factor!r} gives {level!r} here; a mesh's file or node needs a "
                             "factor whose levels are file or node names (words)")
        return level
    chosen = word(file)
    assert chosen is not None  # file is required, a word or a LevelRef
    return chosen, word(node)


class ReachMesh(StrictModel):
    """A glTF model as a reach target's object (``object: {file: pencil.glb, node: pencil}``): ``file`` and
    ``node`` as a mesh item's (either may be ``{factor: NAME}`` of a word factor), turned by ``rotation_deg``
    [yaw, pitch, roll] about its bounding-box centre, scaled so that box's largest extent (in the model's own
    axes, as a mesh item's ``size_m``) is the target's ``size_m``, and that centre placed where the target is
    (straight ahead at ``distance_fraction`` of the arm reach, ``height_m``): the target's position is the
    placed box's centre and its size the box's largest side. Drawn unlit (base colour and texture)."""

    file: FactorWord
    node: FactorWord | None = None
    rotation_deg: tuple[Number, Number, Number] = (0.0, 0.0, 0.0)

    @property
    def word_factors(self) -> tuple[tuple[str, str], ...]:
        """(field, factor name) of ``file`` and ``node`` where they are ``{factor: NAME}``."""
        return _word_factors(self.file, self.node)

    def model_for(self, values: Mapping[str, object]) -> tuple[str, str | None]:
        """(file, node) this trial shows (see :meth:`Mesh.model_for`)."""
        return _model_for(self.file, self.node, values)


class ReachTarget(_Primitive):
    """An object to reach for, straight ahead at a fraction of the participant's arm reach.

    ``distance_fraction``: a number, or ``{factor: target_fraction}``. ``object``: an analytic pencil, sphere
    or cube, or a glTF model (:class:`ReachMesh`), sized and placed by its bounding box."""

    kind: Literal["reach_target"]
    object: Literal["pencil", "sphere", "cube"] | ReachMesh = "pencil"
    size_m: Number = Field(gt=0, le=1, description="longest dimension of the object (a model's bounding box)")
    distance_fraction: Annotated[Number, Field(gt=0, le=1.5)] | "FactorRef"
    height_m: Number = Field(default=-0.15, ge=-2, le=2, description="relative to eye height, up positive")


ReachTarget.model_rebuild()


class MeshLight(StrictModel):
    """The distant white light of ``shading: lambert``: ``direction`` points from the surface towards the
    light, in world (head-at-start) space; colour = albedo x (ambient + (1 - ambient) max(0, n . l))."""

    direction: tuple[Number, Number, Number]
    ambient: Number = Field(default=0.2, ge=0, le=1)


FactorNumber = Union[Number, FactorRef]



class Mesh(_Primitive):
    """A glTF 2.0 model (``.gltf`` or ``.glb``, path relative to the protocol file), or one ``node`` of its
    scene, rasterised beside the analytic primitives with the same per-eye camera (docs/protocols.md, "Meshes").

    Placement (world space: a tracked head moves through it): ``position_m: [x, y, z]`` puts the model's
    origin there; or ``depth`` (and ``centre_deg``, either angle form) puts its bounding-box centre at that
    distance in that direction from the scene origin. ``rotation_deg: [yaw, pitch, roll]`` turns it about
    that point. Size: ``scale`` (model units to metres), ``size_m`` or ``size_deg`` (the bounding box's
    largest extent; size_deg at ``depth``), default scale 1. Numbers may be ``{factor: NAME}``, and so may
    ``file`` and ``node`` (a factor of words: each level a file name or a node name; :meth:`model_for`)."""

    kind: Literal["mesh"]
    file: FactorWord
    node: FactorWord | None = None
    position_m: tuple[FactorNumber, FactorNumber, FactorNumber] | None = None
    centre_deg: Centre | None = None
    depth: Depth | None = None
    rotation_deg: tuple[FactorNumber, FactorNumber, FactorNumber] = (0.0, 0.0, 0.0)
    scale: Annotated[Number, Field(gt=0, le=1e6)] | FactorRef | None = None
    size_m: Annotated[Number, Field(gt=0, le=1000)] | FactorRef | None = None
    size_deg: Annotated[Number, Field(gt=0, lt=180)] | FactorRef | None = None
    shading: Literal["unlit", "lambert"] = "unlit"
    light: MeshLight | None = None

    @model_validator(mode="after")
    def _placement(self) -> "Mesh":
        if self.position_m is not None and (self.depth is not None or self.centre_deg is not None):
            raise ValueError("place a mesh either by position_m or by centre_deg and depth, not both")
        if self.centre_deg is not None and self.depth is None:
            raise ValueError("centre_deg needs a depth: give depth: {m: ...} or {D: ...}")
        if self.position_m is None and self.depth is None:
            raise ValueError("place the mesh: give position_m: [x, y, z] or depth (with centre_deg)")
        if sum(v is not None for v in (self.scale, self.size_m, self.size_deg)) > 1:
            raise ValueError("give at most one of scale, size_m and size_deg")
        if self.size_deg is not None and self.depth is None:
            raise ValueError("size_deg is the angle the model subtends at its depth: it needs depth, not position_m")
        if self.shading == "lambert" and self.light is None:
            raise ValueError("shading: lambert needs a light: {direction: [x, y, z], ambient: 0.2}")
        if self.shading == "unlit" and self.light is not None:
            raise ValueError("a light is used only with shading: lambert; remove it or set shading: lambert")
        return self

    @property
    def word_factors(self) -> tuple[tuple[str, str], ...]:
        """(field, factor name) of ``file`` and ``node`` where they are ``{factor: NAME}``."""
        return _word_factors(self.file, self.node)

    def model_for(self, values: Mapping[str, object]) -> tuple[str, str | None]:
        """(file, node) this trial shows: each ``{factor: NAME}`` replaced by the trial's level (a word).
        A missing or non-word level is a ValueError naming the factor (validation rules both out)."""
        return _model_for(self.file, self.node, values)


Primitive = Annotated[
    Union[Disc, Quad, SinusoidalBorder, Aperture, GridPlanes, TargetField, FixationTarget, Room, ReachTarget, Mesh],
    Field(discriminator="kind"),
]
