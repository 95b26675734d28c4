"""Per-eye cameras: view, off-axis projection and pixel-to-ray matrices, float64.

The display's virtual image is a rectangle fixed in head space at distance d in front of the
eye's centre of rotation C (see :mod:`psyop.optics.display`). The centre of projection P
(C, C + N or C + (-Nx, -Ny, Nz), see :mod:`psyop.optics.nodal`) moves with gaze, so the
frustum through that fixed rectangle is off-axis (Kooima's generalized perspective
projection; the rectangle is axis-aligned in head space, so no rotation is needed).

With o = P - C and 1/d (0 for d = inf), the rectangle's edge tangents seen from P are

    L = (l - o_x / d) / (1 + o_z / d),  R = (r - o_x / d) / (1 + o_z / d),
    B = (b - o_y / d) / (1 + o_z / d),  T = (t - o_y / d) / (1 + o_z / d),

so d = inf keeps the angular extents fixed and only translates the camera. Everything is built
camera-relative: eye space has its origin at P (``view`` = translation by -P), and the
projection depends only on tangents, so millimetre shifts of P are never added to large
coordinates inside a float32 matrix.

Pixel convention (docs/architecture.md): x right, y down, origin at the image's top-left
corner; u = x_px / width_px, v = y_px / height_px.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from psyop.optics.ranges import IPD_M, NC_M
from psyop.optics.display import DisplayProfile
from psyop.optics.rotation import rotation_matrix
from psyop.optics.nodal import (
    DEFAULT_MAX_ROTATION_DEG,
    DEFAULT_MIN_FIXATION_DISTANCE_M,
    Eye,
    RenderingMode,
    eye_centre_m,
    eye_centre_x_m,
    gaze_direction_single,
    gaze_from_fixation,
    parse_eye,
    parse_mode,
    projection_offset_m,
)


@dataclass(frozen=True)
class EyeCamera:
    """Everything the renderer needs for one eye and one frame (arrays are read-only).

    ``view``: head space -> camera-relative eye space (translation by -centre of projection).
    ``projection``: OpenGL-style off-axis projection (clip space, NDC in [-1, 1]).
    ``pixel_to_ray``: 3x3 M with ``direction_head = M @ (u, v, 1)`` (not normalised).
    ``valid``: False when the fixation was unusable and the fallback gaze was used.
    """

    eye: Eye
    mode: RenderingMode
    valid: bool
    centre_of_projection_m: np.ndarray
    width_px: int
    height_px: int
    view: np.ndarray
    projection: np.ndarray
    pixel_to_ray: np.ndarray

    def __post_init__(self) -> None:
        for name in ("centre_of_projection_m", "view", "projection", "pixel_to_ray"):
            arr = np.array(getattr(self, name), dtype=np.float64)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)


@dataclass(frozen=True)
class CameraArrays:
    """Batched camera matrices for n frames of one eye (all float64, all finite)."""

    centre_of_projection_m: np.ndarray  # (n, 3)
    view: np.ndarray  # (n, 4, 4)
    projection: np.ndarray  # (n, 4, 4)
    pixel_to_ray: np.ndarray  # (n, 3, 3)
    tangents: np.ndarray  # (n, 4) L, R, B, T seen from the centre of projection
    valid: np.ndarray  # (n,)


def _check_clip(near_m: ArrayLike, far_m: ArrayLike) -> None:
    near = np.asarray(near_m, dtype=np.float64)
    far = np.asarray(far_m, dtype=np.float64)
    if not (np.all(np.isfinite(near)) and np.all(np.isfinite(far)) and np.all((0.0 < near) & (near < far))):
        raise ValueError(f"need finite 0 < near_m < far_m, got near_m={near_m!r}, far_m={far_m!r}")


def off_axis_tangents(tangents: ArrayLike, offset_m: ArrayLike, d_m: float) -> np.ndarray:
    """(n, 4) tangents (L, R, B, T) of the fixed image rectangle seen from C + offset."""
    l, r, b, t = (float(x) for x in np.asarray(tangents, dtype=np.float64))
    off = np.atleast_2d(np.asarray(offset_m, dtype=np.float64))
    inv_d = 0.0 if math.isinf(d_m) else 1.0 / float(d_m)
    scale = 1.0 / (1.0 + off[:, 2] * inv_d)
    sx = off[:, 0] * inv_d
    sy = off[:, 1] * inv_d
    return np.stack([(l - sx) * scale, (r - sx) * scale, (b - sy) * scale, (t - sy) * scale], axis=-1)


def projection_from_tangents(tangents: ArrayLike, near_m: ArrayLike, far_m: ArrayLike) -> np.ndarray:
    """(n, 4, 4) OpenGL frustum matrices from (n, 4) tangents (glFrustum with l = near * L ...).

    ``near_m`` / ``far_m`` may be scalars or (n,) arrays. The x and y rows depend only on the
    tangents (2 near / (r - l) = 2 / (R - L)), so they are exact whatever the near plane."""
    tan = np.atleast_2d(np.asarray(tangents, dtype=np.float64))
    near_m = np.asarray(near_m, dtype=np.float64)
    far_m = np.asarray(far_m, dtype=np.float64)
    L, R, B, T = tan.T
    n = tan.shape[0]
    p = np.zeros((n, 4, 4))
    p[:, 0, 0] = 2.0 / (R - L)
    p[:, 0, 2] = (R + L) / (R - L)
    p[:, 1, 1] = 2.0 / (T - B)
    p[:, 1, 2] = (T + B) / (T - B)
    p[:, 2, 2] = -(far_m + near_m) / (far_m - near_m)
    p[:, 2, 3] = -2.0 * far_m * near_m / (far_m - near_m)
    p[:, 3, 2] = -1.0
    return p


def eye_camera_arrays(
    display: DisplayProfile,
    eye: Eye | str,
    fixation: ArrayLike,
    ipd_m: float,
    nc_m: float,
    mode: RenderingMode | str,
    near_m: ArrayLike,
    far_m: ArrayLike,
    fallback_direction: ArrayLike | None = None,
    min_fixation_distance_m: float = DEFAULT_MIN_FIXATION_DISTANCE_M,
    max_rotation_deg: float = DEFAULT_MAX_ROTATION_DEG,
) -> CameraArrays:
    """Vectorised camera matrices for n fixations of one eye. Never raises for bad fixations."""
    _check_clip(near_m, far_m)
    centre = eye_centre_m(eye, ipd_m)
    gaze = gaze_from_fixation(fixation, centre, nc_m, fallback_direction, min_fixation_distance_m, max_rotation_deg)
    offset = projection_offset_m(gaze.nodal_offset_m, mode)
    n = offset.shape[0]
    cop = centre + offset
    tan = off_axis_tangents(display.frustum_tangents(parse_eye(eye).value), offset, display.d_m)
    view = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    view[:, :3, 3] = -cop
    l, r, b, t = display.frustum_tangents(parse_eye(eye).value)
    inv_d = 0.0 if math.isinf(display.d_m) else 1.0 / display.d_m
    ray = np.zeros((n, 3, 3))
    ray[:, 0, 0] = r - l
    ray[:, 0, 2] = l - offset[:, 0] * inv_d
    ray[:, 1, 1] = -(t - b)
    ray[:, 1, 2] = t - offset[:, 1] * inv_d
    ray[:, 2, 2] = -(1.0 + offset[:, 2] * inv_d)
    return CameraArrays(cop, view, projection_from_tangents(tan, near_m, far_m), ray, tan, gaze.valid)


def _checked_frame_inputs(fixation_m: ArrayLike, nc_m: float, near_m: float, far_m: float
                          ) -> tuple[np.ndarray, float, float]:
    """The fixation as float64 (3,) or (4,), and the clip distances, validated (``ValueError``)."""
    NC_M.check(nc_m)
    fix = np.asarray(fixation_m, dtype=np.float64)
    if fix.shape not in ((3,), (4,)):
        raise ValueError(f"fixation_m must have shape (3,) or (4,), got {fix.shape}")
    near, far = float(near_m), float(far_m)
    if not (math.isfinite(near) and math.isfinite(far) and 0.0 < near < far):
        raise ValueError(f"need finite 0 < near_m < far_m, got near_m={near_m!r}, far_m={far_m!r}")
    return fix, near, far


def _mode_offset_m(mode: RenderingMode, nc_m: float, direction: tuple[float, float, float]
                   ) -> tuple[float, float, float]:
    """The centre of projection's offset from C: 0 (conventional), N (ocular), (-Nx, -Ny, Nz) (reversed)."""
    ux, uy, uz = direction
    if mode is RenderingMode.CONVENTIONAL:
        return 0.0, 0.0, 0.0
    if mode is RenderingMode.OCULAR:
        return nc_m * ux, nc_m * uy, nc_m * uz
    return -nc_m * ux, -nc_m * uy, nc_m * uz


def make_eye_camera(
    display: DisplayProfile,
    eye: Eye | str,
    fixation_m: ArrayLike,
    ipd_m: float,
    nc_m: float,
    mode: RenderingMode | str,
    near_m: float = 0.01,
    far_m: float = 100.0,
    fallback_direction: ArrayLike | None = None,
) -> EyeCamera:
    """The camera for one eye and one frame.

    ``fixation_m``: the tracked fixation F in head space (3,) in metres, or homogeneous (4,)
    with w = 0 for a direction at infinity (:func:`psyop.optics.nodal.fixation_at_infinity`).
    ``fallback_direction``: gaze direction to use if F is unusable (pass the last valid one);
    default straight ahead. ``ipd_m``, ``nc_m``, ``near_m``, ``far_m`` are configuration and
    are validated (``ValueError``); the fixation never raises.
    """
    IPD_M.check(ipd_m)
    fix, near, far = _checked_frame_inputs(fixation_m, nc_m, near_m, far_m)
    eye_ = parse_eye(eye)
    mode_ = parse_mode(mode)
    # Scalar per-frame path (plain floats); eye_camera_arrays is its vectorised twin and the
    # tests check that both agree.
    cx = eye_centre_x_m(eye_, ipd_m)
    direction, valid = gaze_direction_single(fix, cx, fallback_direction)
    ox, oy, oz = _mode_offset_m(mode_, nc_m, direction)
    l, r, b, t = display.frustum_tangents(eye_.value)
    inv_d = 0.0 if math.isinf(display.d_m) else 1.0 / display.d_m
    scale = 1.0 / (1.0 + oz * inv_d)
    sx, sy = ox * inv_d, oy * inv_d
    L, R, B, T = (l - sx) * scale, (r - sx) * scale, (b - sy) * scale, (t - sy) * scale
    projection = np.array([
        [2.0 / (R - L), 0.0, (R + L) / (R - L), 0.0],
        [0.0, 2.0 / (T - B), (T + B) / (T - B), 0.0],
        [0.0, 0.0, -(far + near) / (far - near), -2.0 * far * near / (far - near)],
        [0.0, 0.0, -1.0, 0.0],
    ])
    px, py, pz = cx + ox, oy, oz
    view = np.array([[1.0, 0.0, 0.0, -px], [0.0, 1.0, 0.0, -py], [0.0, 0.0, 1.0, -pz], [0.0, 0.0, 0.0, 1.0]])
    pixel_to_ray = np.array([[r - l, 0.0, l - sx], [0.0, -(t - b), t - sy], [0.0, 0.0, -(1.0 + oz * inv_d)]])
    return EyeCamera(
        eye=eye_,
        mode=mode_,
        valid=valid,
        centre_of_projection_m=np.array([px, py, pz]),
        width_px=display.width_px,
        height_px=display.height_px,
        view=view,
        projection=projection,
        pixel_to_ray=pixel_to_ray,
    )


def clip_to_pixels(clip: np.ndarray, width_px: int, height_px: int) -> np.ndarray:
    """(n, 4) clip coordinates -> (n, 2) pixels (y down); NaN where w <= 0 (behind P)."""
    w = clip[:, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        x_ndc = clip[:, 0] / w
        y_ndc = clip[:, 1] / w
    px = np.stack([(x_ndc + 1.0) * 0.5 * width_px, (1.0 - y_ndc) * 0.5 * height_px], axis=-1)
    px[~(w > 0)] = np.nan
    return px


def project_to_pixels(camera: EyeCamera, points_head_m: ArrayLike) -> np.ndarray:
    """(n, 3) head-space points -> (n, 2) float64 pixel positions via view, projection, viewport.

    Points at or behind the centre of projection have no image and give NaN.
    """
    pts = np.atleast_2d(np.asarray(points_head_m, dtype=np.float64))
    eye_space = pts - camera.centre_of_projection_m  # == view @ (p, 1), camera-relative
    homo = np.concatenate([eye_space, np.ones((pts.shape[0], 1))], axis=-1)
    clip = homo @ camera.projection.T
    return clip_to_pixels(clip, camera.width_px, camera.height_px)


def paper_frustum_near_plane(
    display: DisplayProfile, eye: Eye | str, nodal_offset_m: ArrayLike, near_m: float
) -> np.ndarray:
    """The paper's eqs. (5)-(6), for comparison only (psyop uses :func:`off_axis_tangents`).

    {l, r} = (z_near + N_z) / (d + N_z) * (d tan(alpha_{l,r}) + N_x), and likewise {b, t} with
    N_y. Returns (n, 4) near-plane values (l, r, b, t); d = inf is taken as the limit
    (z_near + N_z) tan(alpha). ``docs/optics.md`` derives how this differs from the ray geometry.
    """
    l, r, b, t = display.frustum_tangents(parse_eye(eye).value)
    n_off = np.atleast_2d(np.asarray(nodal_offset_m, dtype=np.float64))
    inv_d = 0.0 if math.isinf(display.d_m) else 1.0 / display.d_m
    nx, ny, nz = n_off.T
    factor = (near_m + nz) / (1.0 + nz * inv_d)  # (z_near + Nz) d / (d + Nz), with d tan / d
    return np.stack([factor * (l + nx * inv_d), factor * (r + nx * inv_d),
                     factor * (b + ny * inv_d), factor * (t + ny * inv_d)], axis=-1)


@dataclass(frozen=True)
class ViewGeometry:
    """One eye's view as a headset runtime reports it for one frame (OpenXR ``xrLocateViews`` in the
    head's VIEW space): the eye's centre of rotation C in head space (metres), the orientation of
    its image (unit quaternion w, x, y, z, eye -> head; identity for a display that is not canted)
    and the field of view as tangents (left, right, bottom, top) seen from C in the eye's own frame.
    The image is at optical infinity (a runtime's field of view is a set of directions)."""

    eye: str
    centre_m: tuple[float, float, float]
    orientation_wxyz: tuple[float, float, float, float]
    tangents: tuple[float, float, float, float]

    def __post_init__(self) -> None:
        values = (*self.centre_m, *self.orientation_wxyz, *self.tangents)
        if len(self.centre_m) != 3 or len(self.orientation_wxyz) != 4 or len(self.tangents) != 4:
            raise ValueError(f"view of the {self.eye} eye: need 3 centre, 4 quaternion and 4 tangent values")
        if not all(math.isfinite(float(v)) for v in values):
            raise ValueError(f"view of the {self.eye} eye is not finite: {values}")
        l, r, b, t = self.tangents
        if not (l < r and b < t):
            raise ValueError(f"view of the {self.eye} eye: tangents {self.tangents} need left < right and bottom < top")
        q = np.asarray(self.orientation_wxyz, dtype=np.float64)
        if abs(float(np.linalg.norm(q)) - 1.0) > 1e-3:
            raise ValueError(f"view of the {self.eye} eye: orientation {self.orientation_wxyz} is not a unit quaternion")

    def rotation(self) -> np.ndarray:
        """3x3 rotation eye -> head (columns: the eye frame's x, y, z axes in head space)."""
        return rotation_matrix(self.orientation_wxyz)

    @property
    def canted(self) -> bool:
        return not np.allclose(self.rotation(), np.eye(3), atol=1e-12, rtol=0.0)


def make_view_camera(
    view: ViewGeometry,
    width_px: int,
    height_px: int,
    fixation_m: ArrayLike,
    nc_m: float,
    mode: RenderingMode | str,
    near_m: float = 0.01,
    far_m: float = 100.0,
    fallback_direction: ArrayLike | None = None,
) -> EyeCamera:
    """The camera of one eye for a frame whose view (centre, orientation, field of view) comes
    from a headset runtime rather than from a display profile and an ipd.

    The centre of projection is placed exactly as :func:`make_eye_camera` places it (C, C + N or
    C + (-Nx, -Ny, Nz), with the gaze direction from C to the fixation), C being the view's centre.
    For a view that is not canted, centred at (+-ipd/2, 0, 0) with a profile's tangents, the result
    equals :func:`make_eye_camera` (tests/optics/test_view_camera.py). A canted view rotates the
    image's rays and the view matrix by the view's orientation.

    Examples
    --------
    >>> v = ViewGeometry("right", (0.032, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (-1.0, 1.0, -1.0, 1.0))
    >>> cam = make_view_camera(v, 100, 100, (0.032, 0.0, -1.0), 0.0077, "ocular")
    >>> [round(float(x), 4) for x in cam.centre_of_projection_m]
    [0.032, 0.0, -0.0077]
    """
    fix, near, far = _checked_frame_inputs(fixation_m, nc_m, near_m, far_m)
    eye_ = parse_eye(view.eye)
    mode_ = parse_mode(mode)
    cx, cy, cz = (float(v) for v in view.centre_m)
    if fix.shape == (4,) and fix[3] == 0.0:
        shifted = fix  # a direction at infinity does not depend on where the eye is
    else:
        w = fix[3] if fix.shape == (4,) else 1.0
        shifted = np.array([fix[0] / w, fix[1] / w - cy, fix[2] / w - cz])
    direction, valid = gaze_direction_single(shifted, cx, fallback_direction)
    ox, oy, oz = _mode_offset_m(mode_, nc_m, direction)
    l, r, b, t = (float(v) for v in view.tangents)
    # at optical infinity the angular extents stay fixed: only the camera translates
    projection = np.array([
        [2.0 / (r - l), 0.0, (r + l) / (r - l), 0.0],
        [0.0, 2.0 / (t - b), (t + b) / (t - b), 0.0],
        [0.0, 0.0, -(far + near) / (far - near), -2.0 * far * near / (far - near)],
        [0.0, 0.0, -1.0, 0.0],
    ])
    px, py, pz = cx + ox, cy + oy, cz + oz
    pixel_to_ray = np.array([[r - l, 0.0, l], [0.0, -(t - b), t], [0.0, 0.0, -1.0]])
    view_m = np.array([[1.0, 0.0, 0.0, -px], [0.0, 1.0, 0.0, -py], [0.0, 0.0, 1.0, -pz], [0.0, 0.0, 0.0, 1.0]])
    if view.canted:
        rot = view.rotation()
        pixel_to_ray = rot @ pixel_to_ray
        turn = np.eye(4)
        turn[:3, :3] = rot.T
        view_m = turn @ view_m
    return EyeCamera(eye=eye_, mode=mode_, valid=valid, centre_of_projection_m=np.array([px, py, pz]),
                     width_px=int(width_px), height_px=int(height_px), view=view_m, projection=projection,
                     pixel_to_ray=pixel_to_ray)
