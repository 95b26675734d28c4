"""Map a protocol's scene (psyop.protocol.scene models) for one trial row and time to the
renderer's typed scene.

Conventions (docs/rendering.md):

* One scene per frame for every eye, in head space (world-fixed). Angular sizes and positions
  are seen from the scene origin (:func:`scene_origin_m`): the viewing eye's centre of rotation
  C in a monocular protocol (so with ocular parallax off every element subtends exactly its
  nominal angle), the head origin midway between the eyes in a stereo protocol (so the two
  eyes see the same world-fixed objects, with their disparity).
* A depth of 0 D is optical infinity: the primitive is built ``at_infinity`` (a direction
  cone, drawn behind everything, without parallax), never at a large finite distance.
* Angles (docs/optics.md, "Angles" and "Sizes"): centres are Fick angles (or eccentricity and
  meridian, :mod:`psyop.stimulus.placement`); a frontoparallel disc's diameter across the
  meridian through its centre subtends ``size_deg``, an eye-facing one (``facing: eye``)
  subtends it in every direction; the circling fixation target keeps a constant eccentricity.
* Coplanar primitives: the later-listed one wins (``psyop.rendering.scene``), so a protocol's
  scene order is its layer order at equal depth.
"""

from __future__ import annotations

import math
import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, assert_never

import numpy as np

from psyop.errors import UserError
from psyop.protocol import scene as ps
from psyop.rendering import builders
from psyop.rendering.mesh_scene import MeshInstance
from psyop.rendering.text import TextImage
from psyop.rendering.textures import ImageFiles
from psyop.rendering.scene import (
    Aperture,
    Grating,
    GridMaterial,
    Material,
    NoiseKind,
    NoiseTexture,
    Primitive,
    Scene,
    Shape,
    SineBorder,
    Solid,
    Waveform,
    WindowKind,
)
from psyop.stimulus.output import PIXEL_OUTPUT, Output
from psyop.protocol.factor_fields import resolve_factor_fields
from psyop.protocol.trial import Interval
from psyop.schedule import interval_values
from psyop.stimulus.placement import centre_angles_deg, circle_position_deg
from psyop.records import TrialRow

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from psyop.protocol.model import Protocol
    from psyop.stimulus.meshes import SessionMeshes

INFINITY_M = math.inf  # the distance of 0 D: optical infinity, rendered as directions
DEFAULT_ARM_REACH_M = 0.70


def _distance_m(depth: ps.Depth, values: TrialRow) -> float:
    depth_D = depth.resolve_D(values)
    if not math.isfinite(depth_D) or depth_D < 0:
        raise UserError(f"depth resolves to {depth_D} D for this trial")
    return INFINITY_M if depth_D == 0.0 else 1.0 / depth_D


def _number(value: float | ps.FactorRef) -> float:
    """A numeric field of a scene item whose ``{factor: NAME}`` fields are resolved (resolve_factor_fields)."""
    if isinstance(value, ps.FactorRef):
        raise UserError(f"factor {value.factor!r} was not resolved for this trial")
    return float(value)


def _rgb(rgb: Sequence[float]) -> tuple[float, float, float]:
    """A colour field as the 3-tuple it is (validated by the protocol model)."""
    r, g, b = rgb
    return (r, g, b)


def _trial_seed(values: TrialRow) -> int:
    return int(values.get("trial_seed", 0)) % (2**31)


def surface_deg_per_unit(extent_deg: float) -> float:
    """Surface degrees per local unit (a primitive's half-extent) of a primitive ``extent_deg`` across
    (:func:`psyop.rendering.builders.placed_primitive`: half-extent ``R tan(extent / 2)`` metres): the half-extent
    in surface degrees, ``degrees(tan(extent / 2))``, whatever its distance R (a surface degree is ``R pi / 180``
    metres along the surface; docs/gratings_and_luminance.md).

    Examples
    --------
    >>> round(surface_deg_per_unit(2.0), 6)
    1.000102
    """
    return math.degrees(math.tan(math.radians(extent_deg) / 2.0))


def _pattern_mean(surface: ps.WhiteNoiseSurface | ps.PinkNoiseSurface | ps.GratingSurface, output: Output) -> float:
    """A pattern's mean as the renderer's value: its pixel value, or its luminance through the display's calibration."""
    if surface.luminance is not None:
        return output.luminance_value(_number(surface.luminance.cd_m2))
    return output.pixel_value(ps.PATTERN_MEAN if surface.mean is None else _number(surface.mean))


def _grating(surface: ps.GratingSurface, width_deg: float, height_deg: float, time_s: float,
             output: Output) -> Grating:
    """A grating material: surface-degree frequencies along the primitive's axes, phase (drifted to ``time_s``)
    in cycles, window in surface degrees (:class:`psyop.rendering.scene.Grating`)."""
    cpd = _number(surface.cycles_per_deg)
    theta = math.radians(_number(surface.orientation_deg))
    drift = 0.0 if surface.drift_deg_s is None else _number(surface.drift_deg_s)
    phase_cycles = _number(surface.phase_deg) / 360.0 - cpd * drift * float(time_s)
    mean = _pattern_mean(surface, output)
    window, w1, w2 = WindowKind.NONE, 0.0, 0.0
    if isinstance(surface.window, ps.GaussianWindow):
        window, w1 = WindowKind.GAUSSIAN, _number(surface.window.sigma_deg)
    elif isinstance(surface.window, ps.RaisedCosineWindow):
        window = WindowKind.RAISED_COSINE
        w1, w2 = _number(surface.window.plateau_radius_deg), _number(surface.window.ramp_deg)
    return Grating(mean=mean, amplitude=output.amplitude(mean, _number(surface.michelson)),
                   cycles_u=cpd * math.cos(theta), cycles_v=cpd * math.sin(theta),
                   deg_per_unit_u=surface_deg_per_unit(width_deg), deg_per_unit_v=surface_deg_per_unit(height_deg),
                   phase_cycles=phase_cycles, waveform=Waveform(surface.waveform), window=window,
                   window_1=w1, window_2=w2)


def _material(surface: ps.Surface, values: TrialRow, size_deg: float, base_dir: Path | None,
              images: ImageFiles | None = None, *, height_deg: float | None = None, time_s: float = 0.0,
              output: Output | None = None) -> Material:
    """A rendering material for a protocol surface (noise seeded from the trial seed). ``size_deg``: the
    primitive's extent (its width when ``height_deg`` is given); ``output``: how values become the renderer's
    (pixel values as they are, or normalised luminance on a calibrated display)."""
    output = output if output is not None else PIXEL_OUTPUT
    if isinstance(surface, ps.SolidSurface):
        if surface.luminance is not None:
            grey = output.luminance_value(_number(surface.luminance.cd_m2))
            return Solid((grey, grey, grey))
        assert surface.rgb is not None  # SolidSurface._one_colour
        return Solid(output.pixel_rgb(_rgb(tuple(float(c) for c in surface.rgb))))
    if isinstance(surface, ps.GratingSurface):
        return _grating(surface, size_deg, size_deg if height_deg is None else height_deg, time_s, output)
    seed = _trial_seed(values) + int(getattr(surface, "seed", 0))
    if isinstance(surface, ps.WhiteNoiseSurface):
        size = int(min(1024, max(4, round(size_deg / float(surface.grain_deg)))))
        # peak contrast c around the mean: grey = mean * (1 + c z), z ~ N(0, 1) clipped; RMS c/2
        return NoiseTexture(NoiseKind.WHITE, seed=seed, size_px=size, mean=_pattern_mean(surface, output),
                            contrast=_number(surface.contrast) / 2.0)
    if isinstance(surface, ps.PinkNoiseSurface):
        return NoiseTexture(NoiseKind.PINK, seed=seed, size_px=256, mean=_pattern_mean(surface, output),
                            contrast=_number(surface.contrast) / 2.0)
    if isinstance(surface, ps.ImageSurface):
        repeats = size_deg / float(surface.tile_deg) if surface.tile_deg else 1.0
        return (images if images is not None else ImageFiles(base_dir)).texture(surface.path, repeats)
    raise UserError(f"unsupported surface kind {getattr(surface, 'kind', surface)!r}")


def _rotate_axes(prim: Primitive, angle_deg: float) -> Primitive:
    if angle_deg == 0.0:
        return prim
    a = math.radians(angle_deg)
    rot = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
    return dataclasses.replace(prim, half_u_m=tuple(rot @ np.array(prim.half_u_m)),
                               half_v_m=tuple(rot @ np.array(prim.half_v_m)))  # keeps at_infinity


def _sinusoidal_border(item: ps.SinusoidalBorder, values: TrialRow, origin: np.ndarray,
                       base_dir: Path | None, images: ImageFiles | None = None, time_s: float = 0.0,
                       output: Output = PIXEL_OUTPUT) -> list[Primitive]:
    near_side = item.near_side if item.near_side != "schedule" else str(values.get("near_side", "left"))
    if near_side not in ("left", "right"):
        raise UserError(f"near_side must be left or right, got {near_side!r}")
    phase_deg = float(values.get(f"{item.id}_phase_deg", 0.0 if item.phase == "random" else item.phase))
    near_m = _distance_m(item.near_depth, values)
    far_m = _distance_m(item.far_depth, values)
    size = _number(item.size_deg)
    near_surface = item.left if near_side == "left" else item.right
    far_surface = item.right if near_side == "left" else item.left
    half_tan = math.tan(math.radians(size) / 2.0)
    border = SineBorder(amplitude=math.tan(math.radians(float(item.amplitude_deg))) / half_tan,
                        cycles=size / float(item.period_deg), phase_rad=math.radians(phase_deg), offset=0.0,
                        side=-1 if near_side == "left" else 1)
    far = builders.frontoparallel_rect(far_m, size, size, _material(far_surface, values, size, base_dir, images,
                                                                    time_s=time_s, output=output),
                                       origin_m=origin, name=f"{item.id}_far")
    near = builders.frontoparallel_rect(near_m, size, size, _material(near_surface, values, size, base_dir, images,
                                                                      time_s=time_s, output=output),
                                        origin_m=origin, border=border, name=f"{item.id}_near")
    return [_rotate_axes(far, float(item.orientation_deg)), _rotate_axes(near, float(item.orientation_deg))]


def _grid_planes(item: ps.GridPlanes) -> list[Primitive]:
    depth = float(item.far_m) - float(item.near_m)
    zc = -(float(item.near_m) + depth / 2.0)
    hw, hh, hd = float(item.half_width_m), float(item.half_height_m), depth / 2.0
    out = []
    for plane in item.planes:
        if plane in ("floor", "ceiling"):
            extent_u, extent_v = 2 * hw, 2 * hd
            centre, u, v = (0.0, -hh if plane == "floor" else hh, zc), (hw, 0.0, 0.0), (0.0, 0.0, hd)
        else:
            extent_u, extent_v = 2 * hh, 2 * hd
            centre, u, v = (-hw if plane == "left" else hw, 0.0, zc), (0.0, hh, 0.0), (0.0, 0.0, hd)
        # square cells of spacing_m: lines_per_side along the longer axis, fraction of a cell per line
        n_lines = max(1, round(max(extent_u, extent_v) / float(item.spacing_m)))
        # a line subtends line_width_deg at 1 m: its width in cells of spacing_m
        width_fraction = min(0.5, math.tan(math.radians(float(item.line_width_deg))) / float(item.spacing_m))
        mat = GridMaterial(background=_rgb(item.background_rgb), line_colour=_rgb(item.rgb),
                           lines_per_side=int(n_lines), line_width_fraction=width_fraction)
        out.append(Primitive(Shape.RECT, centre, u, v, mat, name=f"{item.id}_{plane}"))
    return out


def _fixation(item: ps.FixationTarget, values: TrialRow, time_s: float, origin: np.ndarray) -> list[Primitive]:
    az, el = centre_angles_deg(item.centre_deg)
    if item.path is not None:
        start = float(values.get(f"{item.id}_start_deg", 0.0 if item.path.start == "random" else item.path.start))
        direction = int(values.get(f"{item.id}_direction", 1))
        az, el = circle_position_deg(az, el, _number(item.path.eccentricity_deg), start,
                                     direction * _number(item.path.speed_deg_s), time_s)
    dist = _distance_m(item.depth, values)
    size = _number(item.size_deg)
    facing = str(item.facing)
    outer = builders.placed_primitive(Shape.DISC, dist, size, size, Solid(_rgb(item.rgb)), az, el, origin, facing,
                                      name=f"{item.id}_outer")
    # coplanar with the outer disc and listed after it, so it is drawn on top (the coplanar rule)
    inner = builders.placed_primitive(Shape.DISC, dist, size * 0.4, size * 0.4, Solid(_rgb(item.centre_rgb)), az, el,
                                      origin, facing, name=f"{item.id}_inner")
    return [outer, inner]


def depends_on_time(item: ps.Primitive) -> bool:
    """Whether a scene item's primitives change with the time into the interval: a fixation target
    on a path moves (:func:`_fixation`) and a drifting grating's phase moves (``drift_deg_s``, :func:`_grating`);
    these are the uses of ``time_s`` in :func:`build_scene`. A session
    builds every other item once per trial and phase (``psyop.session.scene_renderer``); an item kind
    that starts to use the time must be named here.

    Examples
    --------
    >>> from psyop.protocol import scene as ps
    >>> depends_on_time(ps.Aperture(id="window", kind="aperture", diameter_deg=30))
    False
    """
    if isinstance(item, ps.FixationTarget):
        return item.path is not None
    return any(isinstance(surface, ps.GratingSurface) and surface.drift_deg_s is not None
               and (isinstance(surface.drift_deg_s, ps.FactorRef) or surface.drift_deg_s != 0.0)
               for surface in (getattr(item, name, None) for name in ("surface", "left", "right")))


def _room(item: ps.Room) -> list[Primitive]:
    prims = builders.room_with_pencil(pencil_distance_m=1.0, room_half_width_m=float(item.width_m) / 2.0,
                                      room_depth_m=float(item.depth_m), eye_height_m=float(item.eye_height_m),
                                      room_height_m=float(item.height_m),
                                      table_height_m=None if item.table_height_m is None else float(item.table_height_m))
    return [dataclasses.replace(p, name=f"{item.id}_{p.name}") for p in prims if not p.name.startswith("pencil")]


def _reach_target(item: ps.ReachTarget, values: TrialRow, arm_reach_m: float,
                  meshes: SessionMeshes) -> list[Primitive] | MeshInstance:
    if isinstance(item.distance_fraction, ps.FactorRef):
        fraction = float(values[item.distance_fraction.factor])
    else:
        fraction = float(item.distance_fraction)
    distance = fraction * float(values.get("arm_reach_m", arm_reach_m))
    size = float(item.size_m)
    height = float(item.height_m)
    if isinstance(item.object, ps.ReachMesh):
        from psyop.stimulus.meshes import reach_mesh_instance

        return reach_mesh_instance(item.id, item.object, values, (0.0, height, -distance), size, meshes)
    if item.object == "pencil":
        body = Primitive(Shape.RECT, (0.0, height, -distance), (size * 0.43, 0, 0), (0, size * 0.023, 0),
                         Solid((0.95, 0.8, 0.1)), name=f"{item.id}_body")
        tip = Primitive(Shape.RECT, (size * 0.5, height, -distance), (size * 0.07, 0, 0), (0, size * 0.016, 0),
                        Solid((0.15, 0.1, 0.05)), name=f"{item.id}_tip")
        return [body, tip]
    shape = Shape.DISC if item.object == "sphere" else Shape.RECT
    return [Primitive(shape, (0.0, height, -distance), (size / 2, 0, 0), (0, size / 2, 0), Solid((0.9, 0.3, 0.1)),
                      name=item.id)]


def scene_origin_m(protocol: Protocol, eye_centre_m: ArrayLike) -> np.ndarray:
    """Where a protocol's angular sizes and positions are measured from, in head space.

    Monocular (``eyes: left`` / ``right``): the viewing eye's centre of rotation
    ``eye_centre_m``. Stereo: the head origin (midway between the eyes' centres, which lie at
    psyop.optics.nodal.eye_centre_m), whichever eye is being rendered, so both eyes see one world-fixed scene.
    """
    if str(getattr(protocol, "eyes", "right")) == "stereo":
        return np.zeros(3)
    return np.asarray(eye_centre_m, dtype=np.float64).reshape(3)


def interval_phases(protocol: Protocol) -> list[Interval]:
    """The protocol's ``interval`` phases in order (interval K is element K - 1)."""
    return [phase for phase in protocol.trial.phases if isinstance(phase, Interval)]


def interval_mode(protocol: Protocol, row: TrialRow, interval: int) -> str:
    """The rendering mode of interval ``interval`` (1-based) of a trial row
    (:func:`psyop.schedule.rows.interval_mode`, the one interval-to-mode rule)."""
    from psyop.schedule.rows import interval_mode as rule

    try:
        return rule(row, interval)
    except (KeyError, ValueError) as error:
        raise UserError(f"cannot tell the rendering mode of interval {interval}: {error}; pass --mode") from None


@dataclasses.dataclass(frozen=True)
class _ItemContext:
    """What every scene item of one trial, interval and time is built from."""

    values: TrialRow
    time_s: float
    origin_m: np.ndarray
    base_dir: Path | None
    arm_reach_m: float
    images: ImageFiles | None
    meshes: SessionMeshes
    output: Output = PIXEL_OUTPUT


def _disc(item: ps.Disc, ctx: _ItemContext) -> list[Primitive]:
    mat = _material(item.surface, ctx.values, _number(item.size_deg), ctx.base_dir, ctx.images, time_s=ctx.time_s,
                    output=ctx.output)
    az, el = centre_angles_deg(item.centre_deg)
    return [builders.placed_primitive(Shape.DISC, _distance_m(item.depth, ctx.values), _number(item.size_deg),
                                      _number(item.size_deg), mat, az, el, ctx.origin_m, str(item.facing),
                                      name=item.id)]


def _quad(item: ps.Quad, ctx: _ItemContext) -> list[Primitive]:
    size = max(_number(item.width_deg), _number(item.height_deg))
    az, el = centre_angles_deg(item.centre_deg)
    if isinstance(item.surface, ps.GratingSurface):  # a grating needs each axis's extent (surface degrees per unit)
        mat = _material(item.surface, ctx.values, _number(item.width_deg), ctx.base_dir, ctx.images,
                        height_deg=_number(item.height_deg), time_s=ctx.time_s, output=ctx.output)
    else:
        mat = _material(item.surface, ctx.values, size, ctx.base_dir, ctx.images, output=ctx.output)
    return [builders.placed_primitive(Shape.RECT, _distance_m(item.depth, ctx.values), _number(item.width_deg),
                                      _number(item.height_deg),
                                      mat,
                                      az, el, ctx.origin_m, str(item.facing), name=item.id)]


def _target_field(item: ps.TargetField, ctx: _ItemContext) -> list[Primitive]:
    values = ctx.values
    near_D = item.near.resolve_D(values)
    far_D = item.far.resolve_D(values)
    mat = _material(item.surface, values, _number(item.size_deg), ctx.base_dir, ctx.images, time_s=ctx.time_s,
                    output=ctx.output)
    field = builders.target_field(_trial_seed(values), int(item.count), near_D, far_D, _number(item.size_deg),
                                  float(item.field_deg), ctx.origin_m, material=mat,
                                  min_gap_deg=float(item.min_gap_deg))
    return [dataclasses.replace(p, name=f"{item.id}_{p.name}") for p in field]


def _build_item(item: ps.Primitive, ctx: _ItemContext) -> list[Primitive] | Aperture | MeshInstance:
    """One scene item's part of the scene: its primitives, the aperture, or a placed mesh.

    The one dispatch over the closed set of scene item kinds (``psyop.protocol.scene.Primitive``):
    a kind missing here fails the type check (``assert_never``).
    """
    from psyop.stimulus.meshes import mesh_instance

    out = ctx.output  # the builders' own colours are pixel values: out.primitives turns them into the output's values
    match item:
        case ps.Disc():
            return _disc(item, ctx)
        case ps.Quad():
            return _quad(item, ctx)
        case ps.SinusoidalBorder():
            return _sinusoidal_border(item, ctx.values, ctx.origin_m, ctx.base_dir, ctx.images, ctx.time_s, ctx.output)
        case ps.Aperture():
            return out.aperture(Aperture(radius_deg=_number(item.diameter_deg) / 2.0, colour=_rgb(item.surround_rgb)))
        case ps.GridPlanes():
            return out.primitives(_grid_planes(item))
        case ps.TargetField():
            return _target_field(item, ctx)
        case ps.FixationTarget():
            return out.primitives(_fixation(item, ctx.values, ctx.time_s, ctx.origin_m))
        case ps.Room():
            return out.primitives(_room(item))
        case ps.ReachTarget():
            part = _reach_target(item, ctx.values, ctx.arm_reach_m, ctx.meshes)
            return part if isinstance(part, MeshInstance) else out.primitives(part)
        case ps.Mesh():
            return mesh_instance(item, ctx.values, ctx.origin_m, ctx.meshes)
        case _:
            assert_never(item)


def build_scene(
    protocol: Protocol,
    row: TrialRow,
    time_s: float,
    eye_centre_m: ArrayLike,
    interval: int = 1,
    base_dir: Path | None = None,
    arm_reach_m: float = DEFAULT_ARM_REACH_M,
    background: tuple[float, float, float] = (0.5, 0.5, 0.5),
    show: Sequence[str] | None = None,
    images: ImageFiles | None = None,
    meshes: SessionMeshes | None = None,
) -> Scene:
    """The rendering scene of one trial during interval ``interval`` at ``time_s`` into it.

    ``eye_centre_m``: the rendered eye's centre of rotation in head space. Angular sizes and
    positions are measured from :func:`scene_origin_m` (this centre for a monocular protocol,
    the head origin for a stereo one, so both eyes get the same scene). Only the primitives the
    interval's ``show:`` lists are built, or those ``show`` lists when given (a blank phase's
    ``show:``, with interval ``interval``'s factor values). Every primitive's name is its scene
    item's ``id`` or starts with ``<id>_`` (``psyop audit`` maps primitives back to items by it).

    On a calibrated display (``display: calibration``) the scene's values are normalised luminance and it carries
    the renderer's final pass (``Scene.output``); ``background`` (a pixel value) becomes its code's luminance.

    ``images``: the session's decoded image files (decoded once, reused every frame); without
    it image surfaces are decoded from ``base_dir`` on every call. ``meshes``: the session's
    :class:`psyop.stimulus.meshes.SessionMeshes` (each model loaded once); without it models are read from
    ``base_dir`` on this call.
    """
    from psyop.stimulus.meshes import SessionMeshes

    values = interval_values(row, interval)
    values = {**values, "trial_seed": row.get("trial_seed", 0)}
    output = output_for(protocol, base_dir)
    ctx = _ItemContext(values=values, time_s=time_s, origin_m=scene_origin_m(protocol, eye_centre_m),
                       base_dir=base_dir, arm_reach_m=arm_reach_m, images=images,
                       meshes=meshes if meshes is not None else SessionMeshes(base_dir), output=output)
    phases = interval_phases(protocol)
    if show is None:
        show = phases[interval - 1].show if 0 < interval <= len(phases) else "all"
    prims: list[Primitive] = []
    instances: list[MeshInstance] = []
    aperture = None
    for item in protocol.scene:
        if show != "all" and item.id not in show:
            continue
        try:  # sizes and contrasts given as {factor: NAME} take this trial's (interval's) level
            resolved: ps.Primitive = resolve_factor_fields(item, values)
        except ValueError as error:
            raise UserError(f"scene item '{item.id}': {error}") from None
        part = _build_item(resolved, ctx)
        if isinstance(part, Aperture):
            aperture = part
        elif isinstance(part, MeshInstance):
            instances.append(part)
        else:
            prims += part
    return Scene(tuple(prims), background=output.pixel_rgb(background), aperture=aperture, meshes=tuple(instances),
                 output=output.scene_output())


def output_for(protocol: Protocol, base_dir: Path | None) -> Output:
    """How the protocol's values reach the display: pixel values as they are, or normalised luminance through
    ``display: calibration`` (read once and cached, psyop.protocol.luminance; docs/gratings_and_luminance.md)."""
    if getattr(protocol.display, "calibration", None) is None:
        return PIXEL_OUTPUT
    from psyop.protocol.luminance import protocol_transfer

    return Output(protocol_transfer(protocol, base_dir))


def recalibration_cross_scene(
    eye_centre_m: ArrayLike,
    distance_m: float = 1.0,
    arm_deg: float = 1.0,
    thickness_deg: float = 0.12,
    colour: tuple[float, float, float] = (1.0, 1.0, 1.0),
    background: tuple[float, float, float] = (0.5, 0.5, 0.5),
) -> Scene:
    """The single-point drift recalibration target (paper sec. 5.1): a cross straight ahead of
    the eye, ``arm_deg`` across, at ``distance_m``. Shown with the conventional camera."""
    origin = np.asarray(eye_centre_m, dtype=np.float64)
    ink = Solid(colour)
    bars = (
        builders.frontoparallel_rect(distance_m, arm_deg, thickness_deg, ink, origin_m=origin, name="cross_h"),
        builders.frontoparallel_rect(distance_m, thickness_deg, arm_deg, ink, origin_m=origin, name="cross_v"),
    )
    return Scene(bars, background=background)


#: Where the participant reads the response phase's text (docs/protocols.md, "Trial phases"): straight ahead of
#: the scene origin at 1 m (1 D, well inside the renderer's range; the response phase draws no stimulus to hide it),
#: one em of the font subtending 1 deg.
TEXT_DISTANCE_M = 1.0
TEXT_LETTER_HEIGHT_DEG = 1.0
TEXT_PRIMITIVE_NAME = "response_text"


def text_scene(
    text: TextImage,
    origin_m: ArrayLike,
    distance_m: float = TEXT_DISTANCE_M,
    letter_height_deg: float | None = None,
    background: tuple[float, float, float] = (0.5, 0.5, 0.5),
) -> Scene:
    """A head-fixed panel with ``text`` (psyop.rendering.text), straight ahead of ``origin_m`` at
    ``distance_m``: one em subtends ``letter_height_deg`` there (None: the text's own ``em_deg``, its legible
    size on the display it was laid out for) and the panel keeps the image's aspect ratio.
    ``origin_m``: :func:`scene_origin_m` (the eye's centre when monocular, the head origin in stereo, so both
    eyes see one panel at ``distance_m`` with its disparity)."""
    origin = np.asarray(origin_m, dtype=np.float64).reshape(3)
    em_deg = text.em_deg if letter_height_deg is None else letter_height_deg
    em_m = 2.0 * distance_m * math.tan(math.radians(em_deg) / 2.0)
    half_w, half_h = text.width_em * em_m / 2.0, text.height_em * em_m / 2.0
    # its outline is no stimulus edge: 4x4 samples there (32x32 cost 13x per frame on llvmpipe: bench_text_panel)
    panel = Primitive(Shape.RECT, tuple(origin + np.array([0.0, 0.0, -distance_m])), (half_w, 0.0, 0.0),
                      (0.0, half_h, 0.0), text.texture, name=TEXT_PRIMITIVE_NAME, edge_samples_per_axis=4)
    return Scene((panel,), background=background)


def blank_scene(background: tuple[float, float, float] = (0.5, 0.5, 0.5)) -> Scene:
    """The blank frame between intervals: background only."""
    return Scene((), background=background)
