"""Visual angles: the one angular convention of psyop (docs/optics.md, "Angles").

Every direction is seen from a point (the scene origin for stimuli, the mid-point between the
eyes for gaze) in head space: x right, y up, -z straight ahead.

**Fick angles** ``(azimuth_deg, elevation_deg)``, the form protocols, ``--gaze-deg`` and gaze
logs use. Azimuth is a turn about the head's vertical axis (right positive), then elevation a
turn about the turned horizontal axis (up positive)::

    direction = (cos el * sin az,  sin el,  -cos el * cos az)

Elevation is the angle above the horizontal plane (a latitude); azimuth the angle of the
direction's horizontal projection to the right of straight ahead (a longitude). Valid for
``|elevation| <= 90``. This is not the tangent form (tan az, tan el, -1) psyop used before:
the eccentricity of Fick (az, el) is ``acos(cos az * cos el)``, 22.48 deg for (16, 16), where
the tangent form put (16, 16) at 22.07 deg.

**Polar form** ``(eccentricity_deg, meridian_deg)``, an alternative: eccentricity is the angle
from straight ahead, the meridian the polar angle around straight ahead, 0 = right, 90 = up
(counter-clockwise as the viewer sees it)::

    direction = (sin ecc * cos mer,  sin ecc * sin mer,  -cos ecc)

**Offsets around a centre** (:func:`offset_direction`, the circling fixation target): the
direction at angle ``eccentricity_deg`` from a centre direction, at polar angle ``meridian_deg``
around it, measured from the centre's local right (the direction of increasing azimuth)
towards its local up (increasing elevation). For the centre straight ahead this is the polar
form. A circle of constant eccentricity traversed at a constant rate of polar angle ``w`` moves
at the angular speed ``w * sin(eccentricity)`` (16 deg at 90 deg/s: 24.81 deg/s).

All functions take scalars or numpy arrays (broadcast) and compute in float64.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike


def fick_direction(azimuth_deg: ArrayLike, elevation_deg: ArrayLike) -> np.ndarray:
    """Unit head-space direction(s) of Fick angles; shape ``(..., 3)``.

    Examples
    --------
    >>> fick_direction(0.0, 0.0)
    array([ 0.,  0., -1.])
    >>> bool(np.allclose(fick_direction(90.0, 0.0), [1.0, 0.0, 0.0]))
    True
    """
    az = np.radians(np.asarray(azimuth_deg, dtype=np.float64))
    el = np.radians(np.asarray(elevation_deg, dtype=np.float64))
    az, el = np.broadcast_arrays(az, el)
    return np.stack([np.cos(el) * np.sin(az), np.sin(el), -np.cos(el) * np.cos(az)], axis=-1) + 0.0


def fick_angles_deg(direction: ArrayLike) -> tuple[np.ndarray | float, np.ndarray | float]:
    """(azimuth, elevation) in degrees of head-space direction(s) (any length, not zero).

    Examples
    --------
    >>> az, el = fick_angles_deg(fick_direction(30.0, -20.0))
    >>> round(float(az), 12), round(float(el), 12)
    (30.0, -20.0)
    """
    d = np.asarray(direction, dtype=np.float64)
    azimuth = np.degrees(np.arctan2(d[..., 0], -d[..., 2]))
    elevation = np.degrees(np.arctan2(d[..., 1], np.hypot(d[..., 0], d[..., 2])))
    return _scalar(azimuth), _scalar(elevation)


def polar_direction(eccentricity_deg: ArrayLike, meridian_deg: ArrayLike) -> np.ndarray:
    """Unit head-space direction(s) of the polar form; shape ``(..., 3)``.

    Examples
    --------
    >>> bool(np.allclose(polar_direction(90.0, 90.0), [0.0, 1.0, 0.0]))
    True
    """
    ecc = np.radians(np.asarray(eccentricity_deg, dtype=np.float64))
    mer = np.radians(np.asarray(meridian_deg, dtype=np.float64))
    ecc, mer = np.broadcast_arrays(ecc, mer)
    return np.stack([np.sin(ecc) * np.cos(mer), np.sin(ecc) * np.sin(mer), -np.cos(ecc)], axis=-1) + 0.0


def polar_angles_deg(direction: ArrayLike) -> tuple[np.ndarray | float, np.ndarray | float]:
    """(eccentricity, meridian) in degrees of head-space direction(s); meridian in (-180, 180].

    Examples
    --------
    >>> ecc, mer = polar_angles_deg(fick_direction(16.0, 16.0))
    >>> round(float(ecc), 4)
    22.4784
    """
    d = np.asarray(direction, dtype=np.float64)
    eccentricity = np.degrees(np.arctan2(np.hypot(d[..., 0], d[..., 1]), -d[..., 2]))
    meridian = np.degrees(np.arctan2(d[..., 1], d[..., 0]))
    return _scalar(eccentricity), _scalar(meridian)


def polar_to_fick_deg(eccentricity_deg: ArrayLike, meridian_deg: ArrayLike) -> tuple[np.ndarray | float, np.ndarray | float]:
    """Fick (azimuth, elevation) of a polar-form direction (the conversion a protocol's
    ``{eccentricity_deg, meridian_deg}`` placement goes through).

    Examples
    --------
    >>> az, el = polar_to_fick_deg(16.0, 90.0)
    >>> round(float(az), 12), round(float(el), 12)
    (0.0, 16.0)
    """
    return fick_angles_deg(polar_direction(eccentricity_deg, meridian_deg))


def angle_between_deg(a: ArrayLike, b: ArrayLike) -> np.ndarray | float:
    """The angle between direction(s) ``a`` and ``b`` in degrees (atan2 of |a x b| and a . b,
    accurate at small and large angles).

    Examples
    --------
    >>> round(float(angle_between_deg([0, 0, -1], fick_direction(0.0, 16.0))), 12)
    16.0
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    dot = np.sum(a * b, axis=-1)
    return _scalar(np.degrees(np.arctan2(cross, dot)))


def local_axes(azimuth_deg: float, elevation_deg: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(forward, right, up): the unit direction of Fick (az, el) and its local right (increasing
    azimuth) and up (increasing elevation) axes, an orthonormal frame.

    Examples
    --------
    >>> f, r, u = local_axes(0.0, 0.0)
    >>> r.tolist(), u.tolist()
    ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    """
    az, el = np.radians(float(azimuth_deg)), np.radians(float(elevation_deg))
    forward = fick_direction(azimuth_deg, elevation_deg)
    right = np.array([np.cos(az), 0.0, np.sin(az)]) + 0.0
    up = np.array([-np.sin(el) * np.sin(az), np.cos(el), np.sin(el) * np.cos(az)]) + 0.0
    return forward, right, up


def offset_direction(centre_azimuth_deg: float, centre_elevation_deg: float, eccentricity_deg: ArrayLike,
                     meridian_deg: ArrayLike) -> np.ndarray:
    """Unit direction(s) ``eccentricity_deg`` away from the centre (Fick angles), at polar angle
    ``meridian_deg`` around it (0 = the centre's local right, 90 = its local up); ``(..., 3)``.

    Examples
    --------
    >>> d = offset_direction(10.0, 5.0, 16.0, 123.0)
    >>> round(float(angle_between_deg(d, fick_direction(10.0, 5.0))), 12)
    16.0
    """
    return offset_direction_in(offset_frame(centre_azimuth_deg, centre_elevation_deg, eccentricity_deg), meridian_deg)


def offset_frame(centre_azimuth_deg: float, centre_elevation_deg: float,
                 eccentricity_deg: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """What :func:`offset_direction` computes once for a centre and eccentricity, whatever the meridian:
    (cos ecc * forward, sin ecc, right, up); :func:`offset_direction_in` finishes it (the same numbers as
    :func:`offset_direction`, which is the two; a circling target keeps its frame)."""
    forward, right, up = local_axes(centre_azimuth_deg, centre_elevation_deg)
    ecc = np.radians(np.asarray(eccentricity_deg, dtype=np.float64))[..., None]
    return np.cos(ecc) * forward, np.sin(ecc), right, up


def offset_direction_in(frame: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                        meridian_deg: ArrayLike) -> np.ndarray:
    """:func:`offset_direction` at ``meridian_deg`` in a frame from :func:`offset_frame`; ``(..., 3)``.

    Examples
    --------
    >>> frame = offset_frame(10.0, 5.0, 16.0)
    >>> bool(np.array_equal(offset_direction_in(frame, 123.0), offset_direction(10.0, 5.0, 16.0, 123.0)))
    True
    """
    ahead, sin_ecc, right, up = frame
    mer = np.radians(np.asarray(meridian_deg, dtype=np.float64))[..., None]
    return ahead + sin_ecc * (np.cos(mer) * right + np.sin(mer) * up)


def circle_angular_speed_deg_s(eccentricity_deg: float, polar_speed_deg_s: float) -> float:
    """Angular speed of a target on a circle of constant ``eccentricity_deg`` whose polar angle
    turns at ``polar_speed_deg_s`` (the paper's 16 deg and 90 deg/s: 24.81 deg/s).

    Examples
    --------
    >>> round(circle_angular_speed_deg_s(16.0, 90.0), 2)
    24.81
    """
    return float(abs(polar_speed_deg_s) * np.sin(np.radians(eccentricity_deg)))


def _scalar(x: np.ndarray) -> np.ndarray | float:
    return float(x) if np.ndim(x) == 0 else x
