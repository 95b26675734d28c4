"""Builders for the analytic scene elements the studies need, sized in degrees.

Each builder is pure: geometry in, :class:`~psyop.rendering.scene.Primitive` tuples out.
"Sized in degrees" means the element subtends the given angle as seen from ``origin_m``
(normally the eye's centre of rotation), whatever its distance.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import ArrayLike

from psyop.optics.angles import angle_between_deg, fick_direction, local_axes, polar_to_fick_deg
from psyop.rendering.scene import (
    Colour,
    GridMaterial,
    Material,
    NoiseKind,
    NoiseTexture,
    Primitive,
    Shape,
    SineBorder,
    Solid,
)

ORIGIN = (0.0, 0.0, 0.0)
#: Adaptive samples per pixel axis at the room's edges (straight background edges; the stimulus
#: keeps the renderer's full grid). Error against exact coverage: benchmarks/bench_frame_path.py.
ROOM_EDGE_SAMPLES_PER_AXIS = 4


def direction_from_angles(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """Unit direction in head space of Fick angles (:func:`psyop.optics.angles.fick_direction`):
    azimuth right-positive about the vertical axis, then elevation up-positive; 0/0 = -z.

    Examples
    --------
    >>> direction_from_angles(0.0, 0.0).tolist()
    [0.0, 0.0, -1.0]
    """
    return fick_direction(float(azimuth_deg), float(elevation_deg))


#: How a primitive is oriented (docs/optics.md, "Sizes"): ``frontoparallel`` (in a plane of
#: constant z, the paper's stimuli) or ``eye`` (perpendicular to the line from the scene origin
#: to its centre: it subtends its size in every direction).
FACINGS = ("frontoparallel", "eye")


def place_centre_m(direction: ArrayLike, distance_m: float, origin_m: ArrayLike = ORIGIN,
                   facing: str = "frontoparallel") -> np.ndarray:
    """Where a primitive's centre lies: along ``direction`` from ``origin_m``, on the plane
    ``distance_m`` ahead of the origin (frontoparallel: its depth is the plane's) or at
    ``distance_m`` from the origin (eye-facing: its depth is its centre's distance).

    Examples
    --------
    >>> place_centre_m(direction_from_angles(45.0, 0.0), 1.0).round(12).tolist()
    [1.0, 0.0, -1.0]
    >>> place_centre_m(direction_from_angles(45.0, 0.0), 1.0, facing="eye").round(6).tolist()
    [0.707107, 0.0, -0.707107]
    """
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    o = np.asarray(origin_m, dtype=np.float64)
    if facing == "eye":
        return o + d * distance_m
    if facing != "frontoparallel":
        raise ValueError(f"facing must be one of {FACINGS}, got {facing!r}")
    if not d[2] < 0.0:
        raise ValueError(f"a frontoparallel primitive must lie ahead of the origin (direction {d.tolist()})")
    return o + d * (distance_m / -d[2])


def placed_primitive(
    shape: Shape,
    distance_m: float,
    width_deg: float,
    height_deg: float,
    material: Material,
    azimuth_deg: float = 0.0,
    elevation_deg: float = 0.0,
    origin_m: ArrayLike = ORIGIN,
    facing: str = "frontoparallel",
    border: SineBorder | None = None,
    name: str = "",
) -> Primitive:
    """A disc or rectangle centred on the direction of Fick angles (``azimuth_deg``,
    ``elevation_deg``) seen from ``origin_m``, sized in degrees (docs/optics.md, "Sizes").

    Both orientations have the linear size that subtends the angles face-on at the centre's
    distance R from the origin: half-extents ``R tan(width_deg / 2)`` and ``R tan(height_deg / 2)``.

    * ``facing="eye"``: the primitive is perpendicular to the line of sight to its centre, its
      axes along the centre's local right and up (:func:`psyop.optics.angles.local_axes`); a disc
      subtends ``width_deg`` in every direction. ``distance_m`` is R.
    * ``facing="frontoparallel"``: in the plane ``distance_m`` ahead, axes along x and y. A disc's
      diameter perpendicular to the meridian through its centre subtends ``width_deg`` exactly;
      its diameter along that meridian is foreshortened (:func:`frontoparallel_radial_subtense_deg`).

    ``distance_m`` = inf (0 D): the primitive at optical infinity (``at_infinity``, the same
    angles from every origin).
    """
    if math.isinf(distance_m) and distance_m > 0:
        unit = placed_primitive(shape, 1.0, width_deg, height_deg, material, azimuth_deg, elevation_deg, ORIGIN,
                                facing, border, name)
        return dataclasses.replace(unit, at_infinity=True)
    forward, right, up = local_axes(azimuth_deg, elevation_deg)
    centre = place_centre_m(forward, distance_m, origin_m, facing)
    reach_m = float(np.linalg.norm(centre - np.asarray(origin_m, dtype=np.float64)))
    hw = reach_m * math.tan(math.radians(width_deg) / 2.0)
    hh = reach_m * math.tan(math.radians(height_deg) / 2.0)
    if facing == "eye":
        u, v = right * hw, up * hh
    else:
        u, v = np.array([hw, 0.0, 0.0]), np.array([0.0, hh, 0.0])
    return Primitive(shape, tuple(centre.tolist()), tuple(u), tuple(v), material, border=border, name=name)


def frontoparallel_radial_subtense_deg(size_deg: float, eccentricity_deg: float) -> float:
    """The angle a frontoparallel disc of ``size_deg`` (:func:`placed_primitive`) subtends along
    the meridian through its centre at ``eccentricity_deg`` from straight ahead:
    ``atan(tan e + k) - atan(tan e - k)``, ``k = tan(size / 2) / cos e``; about ``size * cos e``
    for small discs (3.9 % less than ``size_deg`` at 16 deg, 13 % at 30 deg).

    Examples
    --------
    >>> round(frontoparallel_radial_subtense_deg(2.0, 0.0), 12)
    2.0
    >>> round(frontoparallel_radial_subtense_deg(2.0, 16.0), 4)
    1.9226
    """
    e = math.radians(eccentricity_deg)
    k = math.tan(math.radians(size_deg) / 2.0) / math.cos(e)
    return math.degrees(math.atan(math.tan(e) + k) - math.atan(math.tan(e) - k))


def frontoparallel_disc(
    distance_m: float,
    diameter_deg: float,
    material: Material,
    azimuth_deg: float = 0.0,
    elevation_deg: float = 0.0,
    origin_m: ArrayLike = ORIGIN,
    name: str = "",
) -> Primitive:
    """A frontoparallel disc on the plane ``distance_m`` ahead of ``origin_m``, centred on the
    direction of Fick (``azimuth_deg``, ``elevation_deg``): its tangential diameter subtends
    ``diameter_deg`` (:func:`placed_primitive`). ``distance_m`` = inf: at optical infinity."""
    return placed_primitive(Shape.DISC, distance_m, diameter_deg, diameter_deg, material, azimuth_deg,
                            elevation_deg, origin_m, "frontoparallel", name=name)


def eye_facing_disc(
    distance_m: float,
    diameter_deg: float,
    material: Material,
    azimuth_deg: float = 0.0,
    elevation_deg: float = 0.0,
    origin_m: ArrayLike = ORIGIN,
    name: str = "",
) -> Primitive:
    """A disc facing ``origin_m``, its centre ``distance_m`` away in the direction of Fick
    (``azimuth_deg``, ``elevation_deg``): it subtends ``diameter_deg`` in every direction."""
    return placed_primitive(Shape.DISC, distance_m, diameter_deg, diameter_deg, material, azimuth_deg,
                            elevation_deg, origin_m, "eye", name=name)


def frontoparallel_rect(
    distance_m: float,
    width_deg: float,
    height_deg: float,
    material: Material,
    azimuth_deg: float = 0.0,
    elevation_deg: float = 0.0,
    origin_m: ArrayLike = ORIGIN,
    border: SineBorder | None = None,
    name: str = "",
) -> Primitive:
    """A frontoparallel rectangle on the plane ``distance_m`` ahead of ``origin_m``, centred on
    the direction of Fick (``azimuth_deg``, ``elevation_deg``), sized as :func:`placed_primitive`
    says (straight ahead it spans exactly ``width_deg`` x ``height_deg``), optionally clipped by a
    sinusoidal border. ``distance_m`` = inf (0 D): at optical infinity (``at_infinity``)."""
    return placed_primitive(Shape.RECT, distance_m, width_deg, height_deg, material, azimuth_deg, elevation_deg,
                            origin_m, "frontoparallel", border, name)


def detection_stimulus(
    back_D: float,
    relative_D: float,
    origin_m: ArrayLike = ORIGIN,
    diameter_deg: float = 2.0,
    back_colour: Colour = (1.0, 0.0, 0.0),
    noise_seed: int = 0,
) -> tuple[Primitive, Primitive]:
    """The detection/discrimination stimulus: a solid red back disc at ``back_D`` and a
    white-noise front disc ``relative_D`` nearer, both subtending ``diameter_deg`` from
    ``origin_m`` and centred on the same ray, so without ocular parallax the front disc hides
    the back one exactly."""
    back_m = 1.0 / back_D
    front_m = 1.0 / (back_D + relative_D)
    back = frontoparallel_disc(back_m, diameter_deg, Solid(back_colour), origin_m=origin_m, name="back")
    noise = NoiseTexture(NoiseKind.WHITE, seed=noise_seed, size_px=32, mean=0.5, contrast=0.25)
    front = frontoparallel_disc(front_m, diameter_deg, noise, origin_m=origin_m, name="front")
    return back, front


def ordinal_stimulus(
    rear_D: float,
    front_D: float,
    near_side: str,
    origin_m: ArrayLike = ORIGIN,
    field_deg: float = 24.0,
    amplitude_deg: float = 1.0,
    cycles: float = 3.0,
    phase_rad: float = 0.0,
    seeds: tuple[int, int] = (1, 2),
) -> tuple[Primitive, Primitive]:
    """The ordinal-depth stimulus: a rear 1/f-textured surface filling ``field_deg`` and a front
    surface covering the ``near_side`` half, whose border with the rear one is a vertical
    sinusoid (``amplitude_deg`` as seen from ``origin_m``). Both subtend the same angle."""
    if near_side not in ("left", "right"):
        raise ValueError(f"near_side must be 'left' or 'right', got {near_side!r}")
    rear_tex = NoiseTexture(NoiseKind.PINK, seed=seeds[0], size_px=256, mean=0.5, contrast=0.2)
    front_tex = NoiseTexture(NoiseKind.PINK, seed=seeds[1], size_px=256, mean=0.5, contrast=0.2)
    rear = frontoparallel_rect(1.0 / rear_D, field_deg, field_deg, rear_tex, origin_m=origin_m, name="rear")
    half = math.tan(math.radians(field_deg) / 2.0)
    amp = math.tan(math.radians(amplitude_deg)) / half  # in local units of the front plane
    border = SineBorder(amplitude=amp, cycles=cycles, phase_rad=phase_rad, offset=0.0,
                        side=-1 if near_side == "left" else 1)
    front = frontoparallel_rect(1.0 / front_D, field_deg, field_deg, front_tex, origin_m=origin_m,
                                border=border, name="front")
    return rear, front


def fixation_target(
    distance_m: float,
    azimuth_deg: float,
    elevation_deg: float,
    origin_m: ArrayLike = ORIGIN,
    diameter_deg: float = 0.5,
) -> tuple[Primitive, Primitive]:
    """A small red-and-white fixation target: a white disc with a coplanar red centre listed after it."""
    outer = frontoparallel_disc(distance_m, diameter_deg, Solid((1.0, 1.0, 1.0)), azimuth_deg, elevation_deg,
                                origin_m, name="fixation_outer")
    # coplanar with the outer disc and listed after it: drawn on top (the coplanar rule), at any distance
    inner = frontoparallel_disc(distance_m, diameter_deg * 0.4, Solid((1.0, 0.0, 0.0)),
                                azimuth_deg, elevation_deg, origin_m, name="fixation_inner")
    return outer, inner


def grid_planes(
    half_width_m: float = 1.0,
    half_height_m: float = 1.0,
    depth_m: float = 12.0,
    near_m: float = 0.3,
    material: GridMaterial | None = None,
) -> tuple[Primitive, ...]:
    """Four grid planes (floor, ceiling, left and right walls) forming a corridor into the distance."""
    mat = material or GridMaterial(lines_per_side=12)
    zc = -(near_m + depth_m / 2.0)
    hd = depth_m / 2.0
    return (
        Primitive(Shape.RECT, (0, -half_height_m, zc), (half_width_m, 0, 0), (0, 0, hd), mat, name="floor"),
        Primitive(Shape.RECT, (0, half_height_m, zc), (half_width_m, 0, 0), (0, 0, hd), mat, name="ceiling"),
        Primitive(Shape.RECT, (-half_width_m, 0, zc), (0, half_height_m, 0), (0, 0, hd), mat, name="left_wall"),
        Primitive(Shape.RECT, (half_width_m, 0, zc), (0, half_height_m, 0), (0, 0, hd), mat, name="right_wall"),
    )


def target_field(
    seed: int,
    n_targets: int = 20,
    near_D: float = 3.5,
    far_D: float = 0.5,
    diameter_deg: float = 2.6,
    field_deg: float = 60.0,
    origin_m: ArrayLike = ORIGIN,
    max_tries: int = 10_000,
    material: Material | None = None,
    min_gap_deg: float = 0.0,
) -> tuple[Primitive, ...]:
    """Frontoparallel targets at random depths (uniform in diopters between ``far_D`` and
    ``near_D``), each subtending ``diameter_deg``, placed without angular overlap (plus
    ``min_gap_deg``) inside a ``field_deg`` circle. Deterministic for a given seed. Without a
    ``material`` each target gets a random solid shade."""
    rng = np.random.default_rng(seed)
    placed: list[np.ndarray] = []
    out: list[Primitive] = []
    radius = field_deg / 2.0 - diameter_deg / 2.0
    tries = 0
    while len(out) < n_targets and tries < max_tries:
        tries += 1
        r = radius * math.sqrt(rng.uniform())
        phi = rng.uniform(0, 2 * math.pi)
        # polar placement (eccentricity r, meridian phi) and angular gaps between centres (docs/optics.md)
        az, el = (float(x) for x in polar_to_fick_deg(r, math.degrees(phi)))
        here = fick_direction(az, el)
        if any(float(angle_between_deg(here, other)) < diameter_deg * 1.05 + min_gap_deg for other in placed):
            continue
        placed.append(here)
        depth_D = rng.uniform(far_D, near_D)
        shade = float(rng.uniform(0.3, 0.9))
        mat = material if material is not None else Solid((shade, shade * 0.9, 0.4))
        out.append(frontoparallel_disc(1.0 / depth_D if depth_D > 0 else math.inf, diameter_deg, mat, az, el, origin_m, name=f"target{len(out)}"))
    return tuple(out)


def room_with_pencil(
    pencil_distance_m: float,
    pencil_height_m: float = -0.1,
    room_half_width_m: float = 2.0,
    room_depth_m: float = 4.0,
    eye_height_m: float = 1.2,
    room_height_m: float = 2.6,
    table_height_m: float | None = 0.75,
) -> tuple[Primitive, ...]:
    """A simple room (floor, walls, ceiling, back wall, a table and a few objects at other
    depths; ``table_height_m`` None: no table) and a pencil-like reach target: a 15 cm x 7 mm yellow bar with a dark tip,
    floating ``pencil_distance_m`` straight ahead at ``pencil_height_m`` relative to the eyes."""
    floor_y = -eye_height_m
    ceil_y = room_height_m - eye_height_m
    cy = (floor_y + ceil_y) / 2
    hh = (ceil_y - floor_y) / 2
    zc = -room_depth_m / 2
    hd = room_depth_m / 2
    floor = GridMaterial(background=(0.35, 0.25, 0.15), line_colour=(0.2, 0.12, 0.08), lines_per_side=8)
    wall = NoiseTexture(NoiseKind.PINK, seed=11, size_px=128, mean=0.7, contrast=0.1, repeats=3.0)
    prims = [
        Primitive(Shape.RECT, (0, floor_y, zc), (room_half_width_m, 0, 0), (0, 0, hd), floor, name="floor"),
        Primitive(Shape.RECT, (0, ceil_y, zc), (room_half_width_m, 0, 0), (0, 0, hd), Solid((0.9, 0.9, 0.88)),
                  name="ceiling"),
        Primitive(Shape.RECT, (-room_half_width_m, cy, zc), (0, hh, 0), (0, 0, hd), wall, name="left_wall"),
        Primitive(Shape.RECT, (room_half_width_m, cy, zc), (0, hh, 0), (0, 0, hd), wall, name="right_wall"),
        Primitive(Shape.RECT, (0, cy, -room_depth_m), (room_half_width_m, 0, 0), (0, hh, 0),
                  NoiseTexture(NoiseKind.PINK, seed=12, size_px=128, mean=0.6, contrast=0.15, repeats=2.0),
                  name="back_wall"),
        Primitive(Shape.RECT, (0, floor_y + (table_height_m or 0.0), -1.2), (0.6, 0, 0), (0, 0, 0.4), Solid((0.45, 0.3, 0.2)),
                  name="table_top"),
        Primitive(Shape.DISC, (-0.3, floor_y + (table_height_m or 0.0) + 0.15, -1.1), (0.06, 0, 0), (0, 0.06, 0), Solid((0.2, 0.4, 0.8)),
                  name="plate"),
        Primitive(Shape.RECT, (0.35, floor_y + (table_height_m or 0.0) + 0.15, -1.3), (0.04, 0, 0), (0, 0.15, 0), Solid((0.1, 0.5, 0.2)),
                  name="bottle"),
    ]
    if table_height_m is None:  # no table: nothing stands on it either
        prims = [p for p in prims if p.name not in ("table_top", "plate", "bottle")]
    # the room is background with straight edges: a few samples per edge pixel axis suffice
    prims = [dataclasses.replace(p, edge_samples_per_axis=ROOM_EDGE_SAMPLES_PER_AXIS) for p in prims]
    pencil_z = -pencil_distance_m
    prims += [
        Primitive(Shape.RECT, (0, pencil_height_m, pencil_z), (0.065, 0, 0), (0, 0.0035, 0),
                  Solid((0.95, 0.8, 0.1)), name="pencil_body"),
        Primitive(Shape.RECT, (0.075, pencil_height_m, pencil_z), (0.01, 0, 0), (0, 0.0025, 0),
                  Solid((0.15, 0.1, 0.05)), name="pencil_tip"),
    ]
    return tuple(prims)
