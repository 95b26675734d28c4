"""Scene items an aperture hides in every frame that shows them: refused at validation, with the reason; items a
nearer opaque surface covers in every frame: warned (:func:`hidden_behind`).

An aperture (``kind: aperture``) paints everything farther than half its ``diameter_deg`` from straight ahead
(psyop.rendering.scene.Aperture: directions from each eye's display). A fixation target whose whole path, or a
disc or quad whose every point, lies outside that opening in every interval and blank phase that shows it, for
every condition, is never seen: the participant cannot pursue the target or see the stimulus, and only
``psyop audit`` would have noticed ("never visible"), without the reason. The check is conservative, so it
never refuses a design that shows the item somewhere:

- a circling target's nearest approach to straight ahead over its whole circle, ``|eccentricity - centre|``
  (the great circle through both centres), whatever part of the circle a phase covers;
- the item's half size (a quad's half diagonal) toward the opening;
- the largest eye offset from the head's centre (half of the widest ipd, psyop.optics.ranges.IPD_M) seen at
  the item's depth, plus :data:`MARGIN_DEG` for the eye model's nodal offsets and the opening's pixel edge.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

from psyop.optics.ranges import IPD_M
from psyop.protocol.factor_fields import resolve_factor_fields
from psyop.protocol.model import Protocol
from psyop.protocol.scene import Aperture, Disc, FactorRef, FixationTarget, ImageSurface, Quad, centre_eccentricity_deg
from psyop.protocol.trial import Blank, Interval
from psyop.records import JsonObject, Loc

#: degrees added to the parallax margin: ocular parallax (the nodal point's few arcmin) and the opening's
#: anti-aliased pixel edge
MARGIN_DEG = 0.25


def _shown_with(protocol: Protocol, item_id: str, aperture_id: str) -> bool | None:
    """True when every interval and blank phase that shows ``item_id`` also shows ``aperture_id``;
    None when no such phase shows the item (nothing to judge)."""
    showing = []
    for phase in protocol.trial.phases:
        if isinstance(phase, (Interval, Blank)):
            ids = None if phase.show == "all" else set(phase.show)
            if ids is None or item_id in ids:
                showing.append(ids is None or aperture_id in ids)
    return all(showing) if showing else None


def _number(value: float | FactorRef) -> float:
    """A resolved field's number (a factor reference left unresolved is a TypeError: not judged here)."""
    if isinstance(value, FactorRef):
        raise TypeError(f"factor {value.factor!r} not resolved")
    return float(value)


def _nearest_deg(item: FixationTarget | Disc | Quad) -> tuple[float, Loc]:
    """The item's nearest angle to straight ahead (before margins), and the field that sets it."""
    centre_deg = centre_eccentricity_deg(item.centre_deg)
    if isinstance(item, FixationTarget) and item.path is not None:
        return abs(_number(item.path.eccentricity_deg) - centre_deg) - _number(item.size_deg) / 2, \
            ("path", "eccentricity_deg")
    if isinstance(item, Quad):
        half = math.hypot(_number(item.width_deg), _number(item.height_deg)) / 2
    else:
        half = _number(item.size_deg) / 2
    return centre_deg - half, ("centre_deg",)


def _parallax_deg(item: FixationTarget | Disc | Quad, values: JsonObject) -> float:
    depth_D = item.depth.resolve_D(values)
    return math.degrees(math.atan(IPD_M.high / 2 * max(depth_D, 0.0))) + MARGIN_DEG


def _outside(item: FixationTarget | Disc | Quad, radius_deg: float,
             conditions: list[JsonObject]) -> tuple[float, Loc] | None:
    """The item's nearest approach (deg) and its field when it lies outside the opening in every condition."""
    nearest_all: list[float] = []
    field: Loc = ()
    for values in conditions or [{}]:
        try:
            resolved = resolve_factor_fields(item, values)
            nearest, field = _nearest_deg(resolved)
            margin = _parallax_deg(resolved, values)
        except (ValueError, TypeError, KeyError, ZeroDivisionError):
            return None  # an adaptive or unknown level: judged when the level is known (psyop audit)
        if not (math.isfinite(nearest) and nearest - margin > radius_deg):
            return None
        nearest_all.append(nearest)
    return min(nearest_all), field


def _candidates(protocol: Protocol) -> Iterator[tuple[int, FixationTarget | Disc | Quad]]:
    for index, item in enumerate(protocol.scene):
        if isinstance(item, (FixationTarget, Disc, Quad)):
            yield index, item


def hidden_by_aperture(protocol: Protocol, conditions: list[JsonObject]) -> list[tuple[Loc, str]]:
    """(key path, message) for every fixation target, disc or quad an aperture hides in every frame showing it."""
    found: list[tuple[Loc, str]] = []
    apertures = [item for item in protocol.scene if isinstance(item, Aperture)]
    for aperture in apertures:
        radius_deg = float(aperture.diameter_deg) / 2
        for index, item in _candidates(protocol):
            if not _shown_with(protocol, item.id, aperture.id):
                continue
            outside = _outside(item, radius_deg, conditions)
            if outside is None:
                continue
            nearest, field = outside
            what = "fixation target's path" if isinstance(item, FixationTarget) else item.kind
            found.append((("scene", index) + field,
                          f"'{item.id}' is hidden in every frame by aperture '{aperture.id}': the {what} comes no "
                          f"nearer than {nearest:.3g} deg to straight ahead, outside the aperture's {radius_deg:g} deg "
                          f"opening (diameter_deg {float(aperture.diameter_deg):g}); bring '{item.id}' inside the "
                          f"opening, or make the aperture's diameter_deg larger than {2 * nearest:.3g}"))
    return found


#: how far an eye's nodal point moves sideways from the eye's centre as the gaze turns (about 8 mm in the
#: schematic eyes psyop ships; 10 mm taken), added to half the widest ipd in :func:`hidden_behind`'s margin
NODAL_TURN_M = 0.010


def _farthest_deg(item: FixationTarget | Disc | Quad) -> float:
    """The item's farthest angle from straight ahead (a circling target's whole circle, a quad's half diagonal)."""
    centre_deg = centre_eccentricity_deg(item.centre_deg)
    if isinstance(item, FixationTarget) and item.path is not None:
        return centre_deg + _number(item.path.eccentricity_deg) + _number(item.size_deg) / 2
    if isinstance(item, Quad):
        return centre_deg + math.hypot(_number(item.width_deg), _number(item.height_deg)) / 2
    return centre_deg + _number(item.size_deg) / 2


def _covered_deg(occluder: Disc | Quad) -> float | None:
    """The angle around straight ahead that an opaque frontoparallel disc or quad centred straight ahead covers
    (a quad: half its smaller side; in every meridian a direction that near straight ahead meets it); None for an
    occluder this check does not judge (off centre, facing the eye, or an image surface, which may be transparent)."""
    if occluder.facing != "frontoparallel" or centre_eccentricity_deg(occluder.centre_deg) != 0.0 \
            or isinstance(occluder.surface, ImageSurface):
        return None
    if isinstance(occluder, Quad):
        return min(_number(occluder.width_deg), _number(occluder.height_deg)) / 2
    return _number(occluder.size_deg) / 2


def _behind(item: FixationTarget | Disc | Quad, occluder: Disc | Quad,
            conditions: list[JsonObject]) -> tuple[float, float] | None:
    """(the item's farthest angle, the angle the occluder covers) when the occluder is nearer and covers the whole
    item, from either eye and any gaze, in every condition; None otherwise (or when a level is unknown)."""
    farthest_all, covered_all = [], []
    for values in conditions or [{}]:
        try:
            shown, front = resolve_factor_fields(item, values), resolve_factor_fields(occluder, values)
            covered = _covered_deg(front)
            farthest = _farthest_deg(shown)
            nearer_by_D = front.depth.resolve_D(values) - shown.depth.resolve_D(values)
        except (ValueError, TypeError, KeyError, ZeroDivisionError):
            return None  # an adaptive or unknown level: judged when the level is known (psyop audit)
        if covered is None or not nearer_by_D > 0:
            return None
        margin = math.degrees(math.atan((IPD_M.high / 2 + NODAL_TURN_M) * nearer_by_D)) + MARGIN_DEG
        if not (math.isfinite(farthest) and farthest + margin < covered):
            return None
        farthest_all.append(farthest)
        covered_all.append(covered)
    return max(farthest_all), min(covered_all)


def hidden_behind(protocol: Protocol, conditions: list[JsonObject]) -> list[tuple[Loc, str]]:
    """(key path, message) for every fixation target, disc or quad that a nearer opaque disc or quad, centred
    straight ahead and shown whenever it is, covers in every condition from either eye at any gaze (half the
    widest ipd plus :data:`NODAL_TURN_M`, seen across the two depths, plus :data:`MARGIN_DEG`). A warning, not a
    refusal: a participant who moves the head in a world-fixed scene may look around the occluder."""
    found: list[tuple[Loc, str]] = []
    for _, occluder in _candidates(protocol):
        if isinstance(occluder, FixationTarget):
            continue
        for index, item in _candidates(protocol):
            if item is occluder or not _shown_with(protocol, item.id, occluder.id):
                continue
            behind = _behind(item, occluder, conditions)
            if behind is None:
                continue
            farthest, covered = behind
            found.append((("scene", index, "depth"),
                          f"'{item.id}' is hidden behind the nearer {occluder.kind} '{occluder.id}' in every frame "
                          f"that shows it: it reaches no farther than {farthest:.3g} deg from straight ahead, and "
                          f"'{occluder.id}' covers {covered:.3g} deg around it (from either eye, at any gaze); put "
                          f"'{item.id}' nearer than '{occluder.id}', move it out from behind, or make "
                          f"'{occluder.id}' smaller"))
    return found
