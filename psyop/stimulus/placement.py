"""Where a protocol's primitives and fixation target lie, in Fick angles (docs/optics.md, "Angles").

The one place the protocol's angular forms become directions: a centre given as Fick angles
``[azimuth_deg, elevation_deg]`` or as ``{eccentricity_deg, meridian_deg}``, and the circling
fixation target's position at a time. Plain numbers in, plain numbers out, so a factor's value
(an eccentricity or a meridian from the schedule) can be passed straight in.
"""

from __future__ import annotations

import math

from psyop.optics.angles import fick_angles_deg, offset_direction, polar_to_fick_deg
from psyop.protocol import scene as ps


def polar_centre_deg(eccentricity_deg: float, meridian_deg: float) -> tuple[float, float]:
    """Fick (azimuth, elevation) of a centre ``eccentricity_deg`` from straight ahead on
    ``meridian_deg`` (0 right, 90 up).

    Examples
    --------
    >>> polar_centre_deg(16.0, 180.0)
    (-16.0, 0.0)
    """
    az, el = polar_to_fick_deg(float(eccentricity_deg), float(meridian_deg))
    return _clean(float(az)), _clean(float(el))


def centre_angles_deg(centre: ps.Centre) -> tuple[float, float]:
    """Fick (azimuth, elevation) of a protocol ``centre_deg`` in either form (its factor levels filled in;
    an angle still ``{factor: NAME}`` is a ValueError naming the factor).

    Examples
    --------
    >>> centre_angles_deg((12.0, -3.0))
    (12.0, -3.0)
    >>> centre_angles_deg(ps.PolarPoint(eccentricity_deg=10.0, meridian_deg=90.0))
    (0.0, 10.0)
    """
    parts = (centre.eccentricity_deg, centre.meridian_deg) if isinstance(centre, ps.PolarPoint) else tuple(centre)
    unresolved = [p.factor for p in parts if isinstance(p, ps.FactorRef)]
    if unresolved:  # resolve_factor_fields fills in a trial's levels first
        raise ValueError(f"the centre's angle is factor {unresolved[0]!r}: give the trial's level "
                         "(psyop.protocol.factor_fields.resolve_factor_fields)")
    first, second = (float(p) for p in parts if not isinstance(p, ps.FactorRef))  # none is, checked above
    if isinstance(centre, ps.PolarPoint):
        return polar_centre_deg(first, second)
    return first, second


def circle_position_deg(centre_azimuth_deg: float, centre_elevation_deg: float, eccentricity_deg: float,
                        start_deg: float, speed_deg_s: float, time_s: float) -> tuple[float, float]:
    """Fick (azimuth, elevation) of a target circling the centre at constant ``eccentricity_deg``,
    its polar angle ``start_deg + speed_deg_s * time_s`` (0 = the centre's local right, 90 = up;
    a negative speed turns clockwise). Its angular speed is ``|speed_deg_s| * sin(eccentricity)``.

    Examples
    --------
    >>> az, el = circle_position_deg(0.0, 0.0, 16.0, 0.0, 90.0, 1.0)
    >>> round(az, 12), round(el, 12)
    (0.0, 16.0)
    """
    polar_deg = float(start_deg) + float(speed_deg_s) * float(time_s)
    d = offset_direction(float(centre_azimuth_deg), float(centre_elevation_deg), float(eccentricity_deg), polar_deg)
    az, el = fick_angles_deg(d)
    return float(az), float(el)


def _clean(x: float) -> float:
    """Round-off of a conversion (1e-15 deg) set to the exact value it stands for: 0, or an integer."""
    nearest = round(x)
    return float(nearest) if math.isclose(x, nearest, rel_tol=0.0, abs_tol=1e-12) else x
