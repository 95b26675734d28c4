"""The phases of a trial per response kind, and what each phase shows and asks of gaze.

Durations follow the paper (section 5-6): 2IFC 2 s / 0.5 s blank / 2 s; ordinal 3 s;
realism 3 s / 1 s / 3 s; reaching >= 5 s viewing then a blind reach. Each trial starts
with a single-point drift recalibration on a central cross.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from psyop.session.responses.base import ResponseKind


@dataclass(frozen=True)
class PhaseSpec:
    """One timed phase.

    ``show``: 'cross' | 'stimulus' | 'blank' | 'off'. ``mode_column``: the schedule
    column naming the rendering mode shown (None: conventional). ``gaze``: 'cross',
    'pursuit', 'free' or 'none' (what the observer looks at; drives simulated gaze).
    """

    name: str
    duration_s: float
    show: str
    gaze: str
    mode_column: str | None = None

    @property
    def renders(self) -> bool:
        return self.show in ("cross", "stimulus", "blank")


DEFAULT_DURATIONS_S: dict[ResponseKind, dict[str, float]] = {
    ResponseKind.TWO_INTERVAL: {"recalibration": 0.5, "interval1": 2.0, "blank": 0.5, "interval2": 2.0},
    ResponseKind.NEAR_SIDE: {"recalibration": 0.5, "stimulus": 3.0},
    ResponseKind.PREFERENCE: {"recalibration": 0.5, "stimulus_a": 3.0, "blank": 1.0, "stimulus_b": 3.0},
    ResponseKind.REACH: {"recalibration": 0.5, "stimulus": 5.0},
}


def trial_phases(kind: ResponseKind, durations_s: Mapping[str, Any] | None = None) -> tuple[PhaseSpec, ...]:
    """The timed phases before the response, with protocol overrides of their durations."""
    d = dict(DEFAULT_DURATIONS_S[kind])
    for key, value in dict(durations_s or {}).items():
        name = key.removesuffix("_s")
        if name in d and value is not None:
            d[name] = float(value)
    recal = PhaseSpec("recalibration", d["recalibration"], "cross", "cross")
    if kind is ResponseKind.TWO_INTERVAL:
        return (
            recal,
            PhaseSpec("interval1", d["interval1"], "stimulus", "pursuit", "mode_interval1"),
            PhaseSpec("blank", d["blank"], "blank", "pursuit"),
            PhaseSpec("interval2", d["interval2"], "stimulus", "pursuit", "mode_interval2"),
        )
    if kind is ResponseKind.NEAR_SIDE:
        return (recal, PhaseSpec("stimulus", d["stimulus"], "stimulus", "free", "mode"))
    if kind is ResponseKind.PREFERENCE:
        return (
            recal,
            PhaseSpec("stimulus_a", d["stimulus_a"], "stimulus", "free", "mode_a"),
            PhaseSpec("blank", d["blank"], "blank", "free"),
            PhaseSpec("stimulus_b", d["stimulus_b"], "stimulus", "free", "mode_b"),
        )
    return (recal, PhaseSpec("stimulus", d["stimulus"], "stimulus", "free", "rendering"))


def mode_for(phase: PhaseSpec, row: Mapping[str, Any]) -> str:
    """Rendering mode of a phase for this trial ('enabled'/'disabled' map to ocular/conventional)."""
    if phase.mode_column is None or phase.mode_column not in row:
        return "conventional"
    value = str(row[phase.mode_column])
    return {"enabled": "ocular", "disabled": "conventional"}.get(value, value)
