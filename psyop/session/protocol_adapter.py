"""What the session takes from a psyop.protocol.Protocol: phases, fixation target, observer.

Kept in one place so that the loop itself depends only on small typed values
(:class:`~psyop.session.phases.PhaseSpec`, plain dicts) and not on the protocol model.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from psyop.session.phases import PhaseSpec, trial_phases
from psyop.session.responses.base import ResponseKind

_INTERVAL_MODE_COLUMNS: dict[ResponseKind, tuple[str, ...]] = {
    ResponseKind.TWO_INTERVAL: ("mode_interval1", "mode_interval2"),
    ResponseKind.NEAR_SIDE: ("mode",),
    ResponseKind.PREFERENCE: ("mode_a", "mode_b"),
    ResponseKind.REACH: ("rendering",),
}


@dataclass(frozen=True)
class FixationPath:
    eccentricity_deg: float = 16.0
    speed_deg_s: float = 90.0
    distance_m: float = 1.0


def _duration(phase: Any) -> float:
    for name in ("duration_s", "min_duration_s", "expected_s"):
        value = getattr(phase, name, None)
        if value is not None:
            return float(value)
    return 0.0


def phases_from_protocol(protocol: Any, kind: ResponseKind) -> tuple[PhaseSpec, ...]:
    """The protocol's trial phases (up to the response) as PhaseSpecs.

    Participant-paced phases use their minimum or expected duration. Falls back to the
    paper's defaults when the protocol has no ``trial.phases``.
    """
    phases = getattr(getattr(protocol, "trial", None), "phases", None)
    if not phases:
        return trial_phases(kind)
    gaze = "pursuit" if fixation_path(protocol) is not None else "free"
    columns = _INTERVAL_MODE_COLUMNS[kind]
    out: list[PhaseSpec] = []
    n_interval = 0
    for phase in phases:
        k = getattr(phase, "kind", "")
        if k == "drift_recalibration":
            out.append(PhaseSpec("recalibration", _duration(phase), "cross", "cross"))
        elif k == "interval":
            column = columns[min(n_interval, len(columns) - 1)]
            n_interval += 1
            out.append(PhaseSpec(f"interval{n_interval}", _duration(phase), "stimulus", gaze, column))
        elif k == "blank":
            off = bool(getattr(phase, "display_off", False))
            out.append(PhaseSpec("display_off" if off else "blank", _duration(phase), "off" if off else "blank",
                                 "none" if off else gaze))
        elif k == "response":
            break
    return tuple(out)


def fixation_path(protocol: Any) -> FixationPath | None:
    """The circling fixation target of the threshold studies, if the scene has one."""
    for item in getattr(protocol, "scene", None) or []:
        if getattr(item, "kind", None) == "fixation_target" and getattr(item, "path", None) is not None:
            path = item.path
            return FixationPath(float(getattr(path, "eccentricity_deg", 16.0)), float(getattr(path, "speed_deg_s", 90.0)))
    return None


def observer_params(protocol: Any) -> dict[str, Any] | None:
    observer = getattr(protocol, "observer", None)
    if observer is None:
        return None
    return observer.model_dump() if hasattr(observer, "model_dump") else dict(observer)


def study_name(protocol: Any) -> str:
    study = getattr(protocol, "study", None)
    return str(getattr(study, "name", study))
