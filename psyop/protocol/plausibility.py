"""Values that validate but that no eye or display can show, or that were likely meant in another unit: located
warnings, not errors.

``depth: {D: 50}`` (2 cm from the eyes) is a valid depth (psyop.optics.ranges.DEPTH_D) that only
``psyop audit`` noticed; ``psyop validate`` now says so at the value, with the plausible range,
and still exits 0 (a deliberate near stimulus stays possible).
"""

from __future__ import annotations

import math

from psyop.protocol.conditions import expand_conditions
from psyop.protocol.model import Protocol
from psyop.protocol.scene import Aperture, Depth, FactorRef, GridPlanes
from psyop.protocol.source import read_yaml
from psyop.records import JsonObject, Loc

#: The nearest depth a participant can see sharp and fuse: 10 D (0.1 m) is about the near point of a
#: young adult eye (accommodation amplitude ~10 D at 20 years) and about the nearest a headset's
#: near clip plane shows (0.05-0.1 m).
NEAREST_SEEN_D = 10.0
#: the scene-item fields that hold a depth
DEPTH_FIELDS = ("depth", "near", "far", "near_depth", "far_depth")
#: The longest trial phase studies use: an interval, a blank or a participant-paced phase of more than 30 s is far
#: beyond the seconds a psychophysical trial shows (the paper's are 0.5-2 s); a value like 200 was likely meant in
#: milliseconds. (A response's ``timeout_s`` is not checked: waiting long for an answer is a choice.)
LONGEST_PHASE_S = 30.0
#: the trial-phase fields that hold a duration
PHASE_DURATION_FIELDS = ("duration_s", "min_duration_s", "expected_s")
#: the scene-item fields that hold an angular size
SIZE_FIELDS = ("size_deg", "width_deg", "height_deg")


def _nearest_D(depth: Depth, conditions: list[JsonObject]) -> float:
    values = []
    for condition in conditions or [{}]:
        try:
            value = depth.resolve_D(condition)
        except (ZeroDivisionError, KeyError, TypeError, ValueError):
            continue
        if math.isfinite(value):
            values.append(value)  # an adaptive level (NaN until run time) is left out
    return max(values, default=0.0)


def plausibility_warnings(protocol: Protocol) -> list[tuple[Loc, str]]:
    """(key path, message) for every depth nearer than :data:`NEAREST_SEEN_D` in some condition (and
    a grid's nearest plane nearer than 1 / :data:`NEAREST_SEEN_D` m), and every trial phase longer than
    :data:`LONGEST_PHASE_S`.

    Examples
    --------
    >>> from psyop.protocol.scene import Depth
    >>> round(_nearest_D(Depth(D=50), []), 1)
    50.0
    """
    conditions = expand_conditions(protocol.design)
    found: list[tuple[Loc, str]] = []
    for index, item in enumerate(protocol.scene):
        for name in DEPTH_FIELDS:
            depth = getattr(item, name, None)
            if not isinstance(depth, Depth):
                continue
            nearest = _nearest_D(depth, conditions)
            if nearest > NEAREST_SEEN_D:
                found.append((("scene", index, name), _too_near(depth, nearest)))
        near_m = getattr(item, "near_m", None) if isinstance(item, GridPlanes) else None
        if near_m is not None and 0 < near_m < 1.0 / NEAREST_SEEN_D:
            found.append((("scene", index, "near_m"),
                          f"the nearest plane at {near_m:g} m ({1.0 / near_m:g} D) is nearer than an eye can focus or "
                          f"a headset shows; plausible distances are {1.0 / NEAREST_SEEN_D:g} m and farther"))
    from psyop.protocol.visibility import hidden_behind

    return found + _long_phases(protocol) + _oversized(protocol, conditions) + hidden_behind(protocol, conditions)


def _long_phases(protocol: Protocol) -> list[tuple[Loc, str]]:
    """(key path, message) for every trial-phase duration over :data:`LONGEST_PHASE_S`, with the milliseconds reading."""
    found: list[tuple[Loc, str]] = []
    for index, phase in enumerate(protocol.trial.phases):
        for name in PHASE_DURATION_FIELDS:
            value = getattr(phase, name, None)
            if isinstance(value, (int, float)) and value > LONGEST_PHASE_S:
                found.append((("trial", "phases", index, name),
                              f"{name}: {value:g} is {value:g} s ({value / 60:.1f} min) for one {phase.kind} phase, "
                              f"far beyond the seconds a trial shows; if you meant milliseconds, write "
                              f"{name}: {value / 1000:g}"))
    return found


def _largest(value: object, conditions: list[JsonObject]) -> float | None:
    """A size field's largest value: the number, or its factor's largest level over the conditions."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    if isinstance(value, FactorRef):
        levels = [float(c[value.factor]) for c in conditions if isinstance(c.get(value.factor), (int, float))]
        return max((v for v in levels if math.isfinite(v)), default=None)
    return None


def _oversized(protocol: Protocol, conditions: list[JsonObject]) -> list[tuple[Loc, str]]:
    """(key path, message) for every item size larger than the display's whole field of view (its diagonal): a
    value likely meant in arcmin or in pixels. An aperture is left out (an opening wider than the view is a choice
    that hides nothing)."""
    from psyop.protocol.display import resolve_display_profile

    display = resolve_display_profile(protocol.display)
    field_deg = math.hypot(display.horizontal_fov_deg, display.vertical_fov_deg)
    found: list[tuple[Loc, str]] = []
    for index, item in enumerate(protocol.scene):
        if isinstance(item, Aperture):
            continue
        for name in SIZE_FIELDS:
            largest = _largest(getattr(item, name, None), conditions)
            if largest is not None and largest > field_deg:
                found.append((("scene", index, name),
                              f"{name}: {largest:g} deg is wider than the display's whole field of view ({field_deg:.0f} "
                              f"deg across its diagonal); if you meant arcmin, write {name}: {largest / 60:g}; if "
                              f"pixels, about {largest * display.arcmin_per_px / 60:.2g} deg"))
    return found


def _too_near(depth: Depth, nearest: float) -> str:
    """The warning for a depth that reaches ``nearest`` dioptres, with the reading the author likely meant."""
    if depth.m is not None:
        meant = f"if you meant dioptres, write {{D: {depth.m:g}}}"
    elif depth.factor is None and depth.D is not None:
        meant = f"if you meant metres, write {{m: {depth.D:g}}}"
    else:
        names = ", ".join(depth.factor_names)
        meant = f"check the levels of {names} (dioptres when a name ends in _D, metres in _m)"
    return (f"this depth reaches {nearest:g} D ({100.0 / nearest:.1f} cm from the eyes), nearer than an eye can focus "
            f"or a headset shows; plausible depths are 0-{NEAREST_SEEN_D:g} D (optical infinity to "
            f"{100.0 / NEAREST_SEEN_D:g} cm); {meant}")


def located_warnings(protocol: Protocol) -> list[str]:
    """:func:`plausibility_warnings` as ``file:line:column: warning: ...`` lines."""
    warnings = plausibility_warnings(protocol)
    if not warnings:
        return []
    document = read_yaml(protocol.source_text, protocol.source_name)
    lines = []
    for path, message in warnings:
        _, mark = document.nearest(path)
        lines.append(f"{document.location(mark)}: warning: {message}")
    return lines
