"""Typed, immutable scene description for the ray-casting renderer.

A scene is a tuple of analytic planar primitives (discs and parallelograms, optionally clipped
by a sinusoidal border), a background colour and an optional screen-fixed circular aperture.
Every position is in head space (metres, x right, y up, -z forward); the renderer makes them
camera-relative in float64 before anything reaches float32 on the GPU.

Primitives are planar so that a ray through the centre of projection hits each at most once:
occlusion is resolved exactly by taking the nearest hit per sample. Hits at the same depth
(within a relative :data:`COPLANAR_RELATIVE_DEPTH`) go to the later-listed primitive.

A primitive ``at_infinity`` (optical infinity, 0 D) is a set of directions, not of points:
its ``centre_m``/half axes give the primitive as seen at unit distance from the head origin,
and only the directions from there to its points matter (homogeneous w = 0). It is drawn behind
every finite primitive and no translation of the centre of projection moves it (zero parallax).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from psyop.rendering.mesh_scene import MeshInstance

Colour = tuple[float, float, float]

# Two hits whose distances along a ray differ by at most this fraction count as coplanar; the
# later-listed primitive wins (10 um at 1 m: far below any parallax the studies can show, far
# above float32 rounding of the ray-plane distance).
COPLANAR_RELATIVE_DEPTH = 1.0e-5


def _vec3(value: object, name: str) -> tuple[float, float, float]:
    # the common cases in few steps (primitives are built every frame): 3 Python numbers, a float64 3-vector
    if isinstance(value, np.ndarray) and value.shape == (3,) and value.dtype == np.float64:
        x, y, z = value.tolist()
        if math.isfinite(x) and math.isfinite(y) and math.isfinite(z):
            return (x, y, z)
    elif isinstance(value, tuple) and len(value) == 3 and all(isinstance(c, (int, float)) for c in value):
        x, y, z = (float(c) for c in value)
        if math.isfinite(x) and math.isfinite(y) and math.isfinite(z):
            return (x, y, z)
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def _colour(value: object, name: str = "colour") -> Colour:
    rgb = _vec3(value, name)
    if not all(0.0 <= c <= 1.0 for c in rgb):
        raise ValueError(f"{name} components must lie in [0, 1], got {value!r}")
    return rgb


@dataclass(frozen=True)
class Solid:
    """A uniform colour."""

    colour: Colour

    def __post_init__(self) -> None:
        object.__setattr__(self, "colour", _colour(self.colour))


class NoiseKind(str, Enum):
    WHITE = "white"
    PINK = "pink"  # 1/f amplitude spectrum


@dataclass(frozen=True)
class NoiseTexture:
    """Grey-level noise with a given mean and RMS contrast, ``size_px`` texels square, seeded.

    ``repeats`` tiles the texture across the primitive (1 = one copy across its full extent).
    Texels are sampled nearest-neighbour, so white noise keeps its square checks.
    """

    kind: NoiseKind = NoiseKind.WHITE
    seed: int = 0
    size_px: int = 64
    mean: float = 0.5
    contrast: float = 0.3
    repeats: float = 1.0
    tint: Colour = (1.0, 1.0, 1.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "kind", NoiseKind(self.kind))
        object.__setattr__(self, "tint", _colour(self.tint, "tint"))
        if not (4 <= int(self.size_px) <= 1024):
            raise ValueError(f"size_px must be in [4, 1024], got {self.size_px}")


@dataclass(frozen=True)
class ImageTexture:
    """An RGB image (H, W, 3) with values in [0, 1]; stored as a tuple-free bytes copy."""

    pixels: np.ndarray = field(compare=False)
    key: str = "image"
    repeats: float = 1.0

    def __post_init__(self) -> None:
        arr = np.asarray(self.pixels, dtype=np.float32)
        if arr.ndim != 3 or arr.shape[2] != 3 or not np.all(np.isfinite(arr)):
            raise ValueError("ImageTexture.pixels must be a finite (H, W, 3) array")
        arr = np.clip(arr, 0.0, 1.0)
        arr.setflags(write=False)
        object.__setattr__(self, "pixels", arr)


@dataclass(frozen=True)
class GridMaterial:
    """Lines of ``line_colour`` every ``spacing`` local units on a ``background`` colour.

    Local units run from -1 to 1 across the primitive; lines are box-filtered over the pixel
    (or sample) footprint so they do not alias.
    """

    background: Colour = (0.1, 0.1, 0.1)
    line_colour: Colour = (0.8, 0.8, 0.8)
    lines_per_side: int = 10
    line_width_fraction: float = 0.06

    def __post_init__(self) -> None:
        object.__setattr__(self, "background", _colour(self.background, "background"))
        object.__setattr__(self, "line_colour", _colour(self.line_colour, "line_colour"))


class Waveform(str, Enum):
    SINE = "sine"
    SQUARE = "square"


class WindowKind(str, Enum):
    NONE = "none"
    GAUSSIAN = "gaussian"
    RAISED_COSINE = "raised_cosine"


@dataclass(frozen=True)
class Grating:
    """A grey grating computed per ray sample in the fragment shader (never a texture), so its phase is exact
    below the pixel and its outline is the primitive's ray-cast edge.

    In the primitive's local coordinates ``(a, b)`` (-1..1 along ``half_u``/``half_v``) the surface coordinates
    are ``x = a * deg_per_unit_u``, ``y = b * deg_per_unit_v`` (surface degrees, psyop.stimulus.build), and the
    value is ``mean + amplitude * w(x, y) * s(cycles)``, ``cycles = x * cycles_u + y * cycles_v + phase_cycles``:
    ``s = sin(2 pi cycles)`` (``SINE``, point-sampled at each ray) or its sign (``SQUARE``, box-filtered along the
    modulation direction over the pixel's footprint, exact within 32x32 grids at edges). ``w``: 1, a Gaussian
    ``exp(-r^2 / (2 window_1^2))`` or a raised cosine (flat to ``window_1``, falling to 0 over ``window_2``),
    r = |(x, y)|. Values are what the renderer writes (pixel values, or normalised luminance with an
    :class:`OutputTransfer`); the mean plus or minus the amplitude must lie in [0, 1].
    """

    mean: float
    amplitude: float
    cycles_u: float
    cycles_v: float
    deg_per_unit_u: float
    deg_per_unit_v: float
    phase_cycles: float = 0.0
    waveform: Waveform = Waveform.SINE
    window: WindowKind = WindowKind.NONE
    window_1: float = 0.0
    window_2: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "waveform", Waveform(self.waveform))
        object.__setattr__(self, "window", WindowKind(self.window))
        numbers = (self.mean, self.amplitude, self.cycles_u, self.cycles_v, self.deg_per_unit_u, self.deg_per_unit_v,
                   self.phase_cycles, self.window_1, self.window_2)
        if not all(math.isfinite(float(x)) for x in numbers):
            raise ValueError(f"grating numbers must be finite, got {numbers}")
        if not (self.amplitude >= 0.0 and self.mean - self.amplitude >= -1e-12 and self.mean + self.amplitude <= 1 + 1e-12):
            raise ValueError(f"grating mean {self.mean} +- amplitude {self.amplitude} must lie in [0, 1]")
        if not (self.deg_per_unit_u > 0 and self.deg_per_unit_v > 0):
            raise ValueError("grating deg_per_unit_u and deg_per_unit_v must be positive")
        if self.window is WindowKind.GAUSSIAN and not self.window_1 > 0:
            raise ValueError("a Gaussian window needs sigma (window_1) > 0")
        if self.window is WindowKind.RAISED_COSINE and not (self.window_1 >= 0 and self.window_2 > 0):
            raise ValueError("a raised-cosine window needs plateau (window_1) >= 0 and ramp (window_2) > 0")

    def value(self, x_deg: np.ndarray, y_deg: np.ndarray, footprint_cycles: float = 0.0) -> np.ndarray:
        """The analytic value at surface degrees (x, y), float64 (the shader's formula; tests compare with it).
        ``footprint_cycles``: a square wave's box-filter half-width in cycles (0: point-sampled)."""
        x, y = np.asarray(x_deg, dtype=np.float64), np.asarray(y_deg, dtype=np.float64)
        cycles = x * self.cycles_u + y * self.cycles_v + self.phase_cycles
        if self.waveform is Waveform.SINE:
            s = np.sin(2.0 * np.pi * cycles)
        elif footprint_cycles > 1e-6:
            h = footprint_cycles
            s = (_triangle(cycles + h) - _triangle(cycles - h)) / (2.0 * h)
        else:
            s = np.sign(np.sin(2.0 * np.pi * cycles))
        return np.asarray(self.mean + self.amplitude * self.envelope(x, y) * s)

    def envelope(self, x_deg: np.ndarray, y_deg: np.ndarray) -> np.ndarray:
        """The window w(x, y) (1 without a window)."""
        r2 = np.asarray(x_deg, dtype=np.float64) ** 2 + np.asarray(y_deg, dtype=np.float64) ** 2
        if self.window is WindowKind.GAUSSIAN:
            return np.exp(-0.5 * r2 / self.window_1**2)
        if self.window is WindowKind.RAISED_COSINE:
            t = np.clip((np.sqrt(r2) - self.window_1) / self.window_2, 0.0, 1.0)
            return 0.5 + 0.5 * np.cos(np.pi * t)
        return np.ones_like(r2)


def _triangle(cycles: np.ndarray) -> np.ndarray:
    """The antiderivative of the unit square wave sign(sin(2 pi c)), in cycles: f for f = frac(c) < 0.5, else 1 - f."""
    f = np.mod(cycles, 1.0)
    return np.where(f < 0.5, f, 1.0 - f)


Material = Solid | NoiseTexture | ImageTexture | GridMaterial | Grating


@dataclass(frozen=True)
class SineBorder:
    """Keep the part of a primitive where ``side * (a - (offset + amplitude * sin(pi cycles (b + 1) + phase))) >= 0``.

    ``a``/``b`` are the primitive's local coordinates (-1..1 along ``half_u``/``half_v``);
    ``side`` = -1 keeps the part left of the border (smaller a), +1 the part right of it.
    """

    amplitude: float
    cycles: float
    phase_rad: float = 0.0
    offset: float = 0.0
    side: int = -1

    def __post_init__(self) -> None:
        if self.side not in (-1, 1):
            raise ValueError(f"side must be -1 or +1, got {self.side}")


class Shape(str, Enum):
    DISC = "disc"
    RECT = "rect"


@dataclass(frozen=True)
class Primitive:
    """A planar disc (ellipse) or parallelogram: points ``centre + a * half_u + b * half_v``.

    Disc: a^2 + b^2 <= 1. Rect: |a| <= 1 and |b| <= 1. ``half_u`` and ``half_v`` must be
    orthogonal. ``name`` is free text for debugging and tests. ``at_infinity``: the primitive
    lies at optical infinity (see the module docstring): a direction cone, drawn behind every
    finite primitive, without parallax.
    """

    shape: Shape
    centre_m: tuple[float, float, float]
    half_u_m: tuple[float, float, float]
    half_v_m: tuple[float, float, float]
    material: Material
    border: SineBorder | None = None
    name: str = ""
    at_infinity: bool = False
    # anti-aliasing effort at this primitive's edges (adaptive sampling): samples per pixel axis,
    # None = the renderer's full ``samples_per_axis`` (stimulus edges). Background geometry with
    # straight edges (a room) takes a few; the error of each choice: benchmarks/bench_frame_path.py
    edge_samples_per_axis: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "shape", Shape(self.shape))
        object.__setattr__(self, "at_infinity", bool(self.at_infinity))
        if self.edge_samples_per_axis is not None and not 1 <= int(self.edge_samples_per_axis) <= 64:
            raise ValueError(f"primitive {self.name!r}: edge_samples_per_axis must be in [1, 64]")
        for attr in ("centre_m", "half_u_m", "half_v_m"):
            object.__setattr__(self, attr, _vec3(getattr(self, attr), attr))
        u = np.array(self.half_u_m)
        v = np.array(self.half_v_m)
        nu, nv = np.linalg.norm(u), np.linalg.norm(v)
        if nu <= 0 or nv <= 0:
            raise ValueError(f"primitive {self.name!r}: half axes must be non-zero")
        if abs(float(u @ v)) > 1e-9 * nu * nv:
            raise ValueError(f"primitive {self.name!r}: half_u_m and half_v_m must be orthogonal")

    def moved(self, centre_m: tuple[float, float, float], half_u_m: tuple[float, float, float],
              half_v_m: tuple[float, float, float]) -> Primitive:
        """This primitive after a rigid motion (``psyop.rendering.transform.scene_in_head``): the new
        coordinates, everything else kept. A rotation keeps the half axes orthogonal and non-zero, so only
        finiteness is checked again (the full check costs more than the motion, every frame).

        Examples
        --------
        >>> p = Primitive(Shape.DISC, (0, 0, -1), (0.1, 0, 0), (0, 0.1, 0), Solid((1, 0, 0)))
        >>> p.moved((0.0, 0.0, -2.0), (0.0, 0.1, 0.0), (-0.1, 0.0, 0.0)).centre_m
        (0.0, 0.0, -2.0)
        """
        values = (*centre_m, *half_u_m, *half_v_m)
        if len(values) != 9 or not all(isinstance(x, float) and math.isfinite(x) for x in values):
            raise ValueError(f"primitive {self.name!r}: a moved primitive needs 3 finite numbers each, got "
                             f"{centre_m!r}, {half_u_m!r}, {half_v_m!r}")
        out = object.__new__(Primitive)
        out.__dict__.update(self.__dict__, centre_m=tuple(centre_m), half_u_m=tuple(half_u_m), half_v_m=tuple(half_v_m))
        return out

    def closest_distance_m(self, point_m: np.ndarray) -> float:
        """Exact distance from ``point_m`` to the primitive (ignoring the sine clip, which only removes area);
        inf at optical infinity."""
        if self.at_infinity:
            return float("inf")
        c, u, v = (np.array(x) for x in (self.centre_m, self.half_u_m, self.half_v_m))
        rel = np.asarray(point_m, dtype=np.float64) - c
        a = rel @ u / (u @ u)
        b = rel @ v / (v @ v)
        if self.shape is Shape.RECT:
            a, b = np.clip(a, -1, 1), np.clip(b, -1, 1)
        else:
            r = np.hypot(a, b)
            if r > 1:
                a, b = a / r, b / r
        return float(np.linalg.norm(rel - a * u - b * v))

    def farthest_distance_m(self, point_m: np.ndarray) -> float:
        """Distance from ``point_m`` to the primitive's farthest point (corner or rim); inf at optical infinity."""
        if self.at_infinity:
            return float("inf")
        c, u, v = (np.array(x) for x in (self.centre_m, self.half_u_m, self.half_v_m))
        if self.shape is Shape.RECT:
            pts = [c + su * u + sv * v for su in (-1, 1) for sv in (-1, 1)]
        else:
            ang = np.linspace(0, 2 * np.pi, 64, endpoint=False)
            pts = c + np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * v
        return float(np.max(np.linalg.norm(np.asarray(pts) - np.asarray(point_m), axis=-1)))


@dataclass(frozen=True)
class Aperture:
    """A screen-fixed circular window (unaffected by ocular parallax).

    Everything whose direction from the eye's *display* (not from the moving centre of
    projection) lies farther than ``radius_deg`` from (``azimuth_deg``, ``elevation_deg``) is
    painted ``colour``. Azimuth is positive to the right, elevation positive up.
    """

    radius_deg: float
    azimuth_deg: float = 0.0
    elevation_deg: float = 0.0
    colour: Colour = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "colour", _colour(self.colour))
        if not (0.0 < self.radius_deg < 180.0):
            raise ValueError(f"aperture radius_deg must be in (0, 180), got {self.radius_deg}")


#: the final pass's table width: ``OutputTransfer.table`` rows are laid out in rows of this many texels
OUTPUT_TABLE_ROW = 128


@dataclass(frozen=True)
class OutputTransfer:
    """The renderer's final pass on a calibrated display (docs/gratings_and_luminance.md): the ray-cast's values are
    normalised luminance ``l``; ``table`` (n, 3) holds per output channel the display's normalised luminance at the
    codes ``255 k / (n - 1)``, non-decreasing (the calibration's forward model, finely sampled). The final pass
    inverts it per pixel: a binary search for the bracketing entries, then linear interpolation between them, gives
    the fractional code (exact at every entry: a luminance of a whole code gives that code); values below the first
    entry give code 0, above the last 255. The code is then made an integer by ordered dithering (``dither``: an
    8 x 8 Bayer threshold, offset per frame by the golden ratio, so each aligned 8 x 8 block's mean code is within
    1/64 of the fractional one and each pixel's mean over frames tends to it), or rounded; a code within 0.001 of an
    integer is that integer (steady backgrounds). Equal transfers compare by ``key`` (the calibration's path), so a
    scene built each frame keeps the uploaded table."""

    table: np.ndarray = field(compare=False)
    key: str = "transfer"
    dither: bool = True

    def __post_init__(self) -> None:
        table = np.asarray(self.table, dtype=np.float32)
        if table.ndim == 1:
            table = np.repeat(table[:, None], 3, axis=1)
        if table.ndim != 2 or table.shape[1] != 3 or not 2 <= table.shape[0] <= OUTPUT_TABLE_ROW**2 \
                or not np.all(np.isfinite(table)):
            raise ValueError(f"OutputTransfer.table must be a finite (n, 3) array, 2 <= n <= {OUTPUT_TABLE_ROW**2}")
        if np.any(np.diff(table, axis=0) < 0) or np.any(table[-1] <= table[0]):
            raise ValueError("OutputTransfer.table must rise with the code (non-decreasing in float32: near a black "
                             "level the finest steps may round equal)")
        table = np.ascontiguousarray(table)
        table.setflags(write=False)
        object.__setattr__(self, "table", table)

    def codes(self, values: np.ndarray) -> np.ndarray:
        """The fractional codes of normalised luminances (the final pass's inversion, float64), per channel."""
        v = np.asarray(values, dtype=np.float64)
        grid = np.linspace(0.0, 255.0, self.table.shape[0])
        return np.stack([np.interp(v[..., c], self.table[:, c].astype(np.float64), grid) for c in range(3)], axis=-1)


@dataclass(frozen=True)
class Scene:
    """What to draw: primitives (nearest hit wins), a background, an optional aperture, and mesh items
    (psyop.rendering.mesh_scene; rasterised first, sharing the primitives' depth: docs/rendering.md).
    ``output``: None (values are pixel values, written as they are) or the calibrated display's
    :class:`OutputTransfer` (values are normalised luminance, mapped to codes by the final pass)."""

    primitives: tuple[Primitive, ...]
    background: Colour = (0.5, 0.5, 0.5)
    aperture: Aperture | None = None
    meshes: tuple[MeshInstance, ...] = ()
    output: OutputTransfer | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "primitives", tuple(self.primitives))
        object.__setattr__(self, "meshes", tuple(self.meshes))
        for m in self.meshes:
            if not isinstance(m, MeshInstance):
                raise TypeError(f"scene meshes must be MeshInstance, got {type(m).__name__}")
        object.__setattr__(self, "background", _colour(self.background, "background"))
        for p in self.primitives:
            if not isinstance(p, Primitive):
                raise TypeError(f"scene primitives must be Primitive, got {type(p).__name__}")

    def depth_range_m(self, point_m: np.ndarray) -> tuple[float, float]:
        """(nearest, farthest) distance of any primitive point from ``point_m``; (inf, inf) if empty.

        Vectorised over the primitives, with the same float64 operations in the same order as
        :meth:`Primitive.closest_distance_m` and :meth:`Primitive.farthest_distance_m`, so the result
        equals the per-primitive form (benchmarks/former.py) bit for bit (tests/rendering/test_renderer_cache_equality.py).

        Examples
        --------
        >>> from psyop.rendering.builders import frontoparallel_disc
        >>> scene = Scene((frontoparallel_disc(2.0, 1.0, Solid((1, 0, 0))),))
        >>> near, far = scene.depth_range_m(np.zeros(3))
        >>> round(near, 6), far > near
        (2.0, True)
        """
        if self.meshes:
            return self._depth_range_with_meshes_m(point_m)
        finite = [p for p in self.primitives if not p.at_infinity]
        if not finite:
            return (float("inf"), float("inf"))
        point = np.asarray(point_m, dtype=np.float64)
        c = np.array([p.centre_m for p in finite])
        u = np.array([p.half_u_m for p in finite])
        v = np.array([p.half_v_m for p in finite])
        near = float(np.min(_closest_distances_m(c, u, v, np.array([p.shape is Shape.RECT for p in finite]), point)))
        far = float(np.max(_farthest_distances_m(c, u, v, np.array([p.shape is Shape.RECT for p in finite]), point)))
        if len(finite) < len(self.primitives):  # a primitive at optical infinity: the farthest point is at infinity
            far = float("inf")
        return (near, far)

    def _depth_range_with_meshes_m(self, point_m: np.ndarray) -> tuple[float, float]:
        """:meth:`depth_range_m` of a scene with meshes: each mesh bounded by the sphere around its placed
        bounding box (conservative: a point inside a sphere gives nearest 0, so no frame is reused)."""
        near, far = Scene(self.primitives).depth_range_m(point_m)
        point = np.asarray(point_m, dtype=np.float64)
        for mesh in self.meshes:
            centre, radius = mesh.bounding_sphere_m()
            distance = float(np.linalg.norm(centre - point))
            near = min(near, max(0.0, distance - radius))
            far = max(far, distance + radius)  # inf without finite primitives: a wider range, still a bound
        return (near, far)


def _rowwise_dot(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Row-wise dot products of (n, 3) arrays, computed like ``x[i] @ y[i]`` (the same rounding)."""
    return (x[:, None, :] @ y[:, :, None])[:, 0, 0]


def _closest_distances_m(c: np.ndarray, u: np.ndarray, v: np.ndarray, rect: np.ndarray,
                         point_m: np.ndarray) -> np.ndarray:
    """:meth:`Primitive.closest_distance_m` of n finite primitives at once (same operations, same order)."""
    rel = point_m - c
    a = _rowwise_dot(rel, u) / _rowwise_dot(u, u)
    b = _rowwise_dot(rel, v) / _rowwise_dot(v, v)
    r = np.hypot(a, b)
    outside = ~rect & (r > 1)
    a = np.where(rect, np.clip(a, -1, 1), np.where(outside, a / np.where(outside, r, 1.0), a))
    b = np.where(rect, np.clip(b, -1, 1), np.where(outside, b / np.where(outside, r, 1.0), b))
    d = rel - a[:, None] * u - b[:, None] * v
    return np.sqrt(_rowwise_dot(d, d))


_RIM_ANGLES_RAD = np.linspace(0, 2 * np.pi, 64, endpoint=False)
_CORNER_SIGNS = np.array([(su, sv) for su in (-1, 1) for sv in (-1, 1)], dtype=np.float64)


def _farthest_distances_m(c: np.ndarray, u: np.ndarray, v: np.ndarray, rect: np.ndarray,
                          point_m: np.ndarray) -> np.ndarray:
    """:meth:`Primitive.farthest_distance_m` of n finite primitives at once (same points, same rounding)."""
    out = np.empty(len(c))
    if rect.any():
        cr, ur, vr = c[rect], u[rect], v[rect]
        pts = (cr[:, None, :] + _CORNER_SIGNS[None, :, :1] * ur[:, None, :]) + _CORNER_SIGNS[None, :, 1:] * vr[:, None, :]
        out[rect] = np.max(np.linalg.norm(pts - point_m, axis=-1), axis=1)
    disc = ~rect
    if disc.any():
        cd, ud, vd = c[disc], u[disc], v[disc]
        pts = (cd[:, None, :] + np.cos(_RIM_ANGLES_RAD)[None, :, None] * ud[:, None, :]) \
            + np.sin(_RIM_ANGLES_RAD)[None, :, None] * vd[:, None, :]
        out[disc] = np.max(np.linalg.norm(pts - point_m, axis=-1), axis=1)
    return out
