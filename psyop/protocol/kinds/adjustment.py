"""``adjustment``: the method of adjustment. The participant changes one quantity of one scene item (a depth, a
size, a contrast, a position: any field the item reads as ``{factor: VARIABLE}``) from a start value the schedule
sets, with keys, response-box buttons (steps of ``step``), and confirms; the final value is the answer
(``response``, and ``response_value`` as a number), its whole path and the time are logged. The analysis
(analysis/adjustment.py) reports the point of subjective equality (PSE), the bias from the reference and the
precision (SD) per participant and condition, their means, and the RM-ANOVA of the PSE (psyop.statistics.adjustment).

The adjusted quantity is a named variable (``variable: match_D``) that the item's field reads as
``{factor: match_D}``: the existing factor-field machinery (psyop.protocol.factor_fields, Depth's ``factor``)
draws it, so no rendering code knows of adjustments. The schedule writes each trial's start value in the
variable's column (and ``<variable>_start``), the reference in ``<variable>_reference``; during the response phase
the session shows interval 1's scene with the variable's current value (:class:`AdjustmentState`) written into the
row, frame by frame (psyop.session.loop).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from statistics import NormalDist
from typing import Any, ClassVar, Literal

import numpy as np
from pydantic import Field, field_validator

from psyop.protocol.base import Number, StrictModel, format_level, has_unit_suffix
from psyop.protocol.kinds.base import (AnalysisTarget, Checks, IntervalSpec, KindResponse, ModeFromFactor,
                                       ObserverBase, ResponseKindSpec, ScheduleInput, Scored, StudyInputs,
                                       figure_target, mode_factor_of)
from psyop.protocol.kinds.modes import mode_values
from psyop.protocol.scene import Depth, FactorRef
from psyop.records import Loc, TrialRow

#: the raw inputs' names after the kind's maps: one step up or down, the thumbstick's deflection, confirm
UP, DOWN, AXIS, CONFIRM = "up", "down", "axis", "confirm"
#: a thumbstick deflection below this (of 1) is read as rest: a resting stick never reads exactly 0
AXIS_DEAD_ZONE = 0.1


def start_column(variable: str) -> str:
    """The schedule column of a trial's start value (the variable's own column holds it too)."""
    return f"{variable}_start"


def reference_column(variable: str) -> str:
    """The schedule column of a trial's reference value (what a perfect match gives)."""
    return f"{variable}_reference"


def path_column(variable: str) -> str:
    """The trial-log column of the whole path: JSON ``[[t_s, value], ...]`` (t_s from the response phase's
    start; the start value first, then every change). The schedule holds it empty; the session fills it."""
    return f"{variable}_path"


class UniformStart(StrictModel):
    """A start drawn per trial, uniformly in ``[low, high]`` (the kind's own seeded schedule stream)."""

    uniform: tuple[Number, Number]


class Bounds(StrictModel):
    """The values the adjustment can reach (a press beyond them stays at the bound)."""

    min: Number
    max: Number


class AdjustmentResponse(KindResponse):
    """Adjust ``variable`` (read by scene item ``item``'s ``field`` as ``{factor: variable}``) from ``start``
    within ``bounds`` until it matches ``reference``; the stimulus is interval 1's (``stimulus``: its mode and
    factor overrides), shown during the response phase too."""

    kind: Literal["adjustment"]
    intervals_needed: ClassVar[int] = 1
    question: str = "Adjust it until it matches, then confirm."
    variable: str = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")
    item: str
    field: str
    stimulus: IntervalSpec
    start: Number | UniformStart | FactorRef
    bounds: Bounds
    step: Number = Field(gt=0)
    #: the change per second at full thumbstick deflection (None: 10 steps per second)
    rate_per_s: Number | None = Field(default=None, gt=0)
    reference: Number | FactorRef

    def interval_specs(self) -> tuple[IntervalSpec, ...]:
        return (self.stimulus,)

    def factors_read(self) -> set[str]:
        used = mode_factor_of(self.stimulus.mode) | set(self.stimulus.set)
        used |= {ref.factor for ref in (self.start, self.reference) if isinstance(ref, FactorRef)}
        return used

    def scene_variables(self) -> dict[str, tuple[float, float]]:
        return {self.variable: (float(self.bounds.min), float(self.bounds.max))}

    def rate(self) -> float:
        """The change per second at full deflection."""
        return float(self.rate_per_s) if self.rate_per_s is not None else 10.0 * float(self.step)


@dataclass(frozen=True)
class AdjustmentSpec:
    """What the session needs of an adjustment response (psyop.session.plan carries it): the variable, the
    bounds, the step and the thumbstick's rate."""

    variable: str
    low: float
    high: float
    step: float
    rate_per_s: float

    @classmethod
    def of(cls, response: AdjustmentResponse) -> AdjustmentSpec:
        return cls(response.variable, float(response.bounds.min), float(response.bounds.max), float(response.step),
                   response.rate())

    def state(self, start: float, t0_s: float) -> AdjustmentState:
        """A trial's adjustment from ``start`` (clipped to the bounds), its response phase begun at ``t0_s``."""
        return AdjustmentState(self, t0_s, _clip(float(start), self.low, self.high))

    def as_dict(self) -> dict[str, Any]:  # Any: session.json values
        return {"variable": self.variable, "bounds": [self.low, self.high], "step": self.step,
                "rate_per_s": self.rate_per_s}


def _clip(value: float, low: float, high: float) -> float:
    return min(max(value, low), high)


@dataclass
class AdjustmentState:
    """One trial's adjustment: raw inputs (already the kind's names: :data:`UP`, :data:`DOWN`, :data:`AXIS`,
    :data:`CONFIRM`) in, the value, the path and the confirmation out.

    A press moves the value one ``step`` (clipped to the bounds; each press is a path entry, also one that a
    bound stops). An :data:`AXIS` input sets the thumbstick's deflection d in [-1, 1] from its time on: the value
    then moves continuously at ``rate_per_s`` x d (0 inside :data:`AXIS_DEAD_ZONE`), a path entry at each input
    that changed it. Times are the session clock's; the path's are from ``t0_s`` (the response phase's start).

    Examples
    --------
    >>> spec = AdjustmentSpec("match_D", 0.0, 2.0, 0.1, 0.5)
    >>> s = spec.state(1.0, t0_s=0.0)
    >>> for name, t in (("up", 0.5), ("up", 0.7), ("down", 1.0), ("confirm", 2.0)):
    ...     s.apply(name, t)
    >>> s.value, s.confirmed_s, s.path
    (1.1, 2.0, [(0.0, 1.0), (0.5, 1.1), (0.7, 1.2), (1.0, 1.1)])
    >>> s = spec.state(1.0, t0_s=0.0)
    >>> s.apply("axis", 1.0, 1.0); s.apply("axis", 3.0, 0.0)  # full deflection for 2 s at 0.5 per s
    >>> s.value_at(5.0), s.path[-1]
    (2.0, (3.0, 2.0))
    """

    spec: AdjustmentSpec
    t0_s: float
    value: float
    path: list[tuple[float, float]] = field(default_factory=list)
    confirmed_s: float | None = None
    deflection: float = 0.0
    _moved_s: float = 0.0

    def __post_init__(self) -> None:
        self.path = [(0.0, self.value)]
        self._moved_s = self.t0_s

    @property
    def start(self) -> float:
        return self.path[0][1]

    def _moved(self, t_s: float) -> float:
        """The value at ``t_s`` under the current deflection (nothing changed)."""
        d = self.deflection if abs(self.deflection) >= AXIS_DEAD_ZONE else 0.0
        if d == 0.0 or t_s <= self._moved_s:
            return self.value
        return _clip(self.value + self.spec.rate_per_s * d * (t_s - self._moved_s), self.spec.low, self.spec.high)

    def value_at(self, t_s: float) -> float:
        """The value shown at ``t_s`` (a frame's display time): the thumbstick's movement carried on to it."""
        return self.value if self.confirmed_s is not None else self._moved(t_s)

    def apply(self, name: str, t_s: float, amount: float = 1.0) -> None:
        """One raw input at ``t_s`` (``amount``: an axis's deflection; a press's is 1). Inputs after the
        confirmation are ignored; one earlier than the last is taken at the last's time (time never runs back)."""
        if self.confirmed_s is not None:
            return
        t_s = max(float(t_s), self._moved_s)
        moved = self._moved(t_s)
        changed = moved != self.value
        self.value, self._moved_s = moved, t_s
        if name in (UP, DOWN):
            sign = 1.0 if name == UP else -1.0
            self.value = _clip(round(self.value + sign * self.spec.step, 12), self.spec.low, self.spec.high)
            changed = True
        elif name == AXIS:
            self.deflection = max(-1.0, min(1.0, float(amount)))
        elif name == CONFIRM:
            self.confirmed_s = t_s
        if changed:
            self.path.append((t_s - self.t0_s, self.value))

    def answer(self) -> str:
        """The value as the trial log's ``response`` (``response_value`` reads it back as the same float)."""
        return repr(float(self.value))

    def path_json(self) -> str:
        """The path as the trial log's ``<variable>_path``: JSON ``[[t_s, value], ...]``."""
        return path_json(self.path)


def path_json(path: list[tuple[float, float]]) -> str:
    """A path as JSON ``[[t_s, value], ...]`` (times to the microsecond, values at full precision)."""
    return json.dumps([[round(float(t), 6), float(v)] for t, v in path], separators=(",", ":"))


def _level_key(value: object) -> str:
    if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool):
        return format_level(float(value))
    return str(value)


class AdjustmentObserver(ObserverBase):
    """A simulated adjuster: final = reference + bias + o + e, ``bias`` one number or per level of ``factor``,
    o ~ N(0, ``between_subject_sd``) once per participant, e ~ N(0, ``sd``) per trial (from the trial's keyed
    uniform), clipped to the bounds. Its path steps from the start towards the final value one ``step`` every
    ``step_s`` seconds and ends on it (deterministic)."""

    kind: Literal["adjustment"]
    declared: ClassVar[bool] = True
    #: the factor whose level picks the bias (None: ``bias`` is one number for every trial)
    factor: str | None = None
    bias: dict[str, Number] | Number = 0.0
    sd: Number = Field(gt=0)
    between_subject_sd: Number = Field(default=0.0, ge=0)
    #: seconds per step of the simulated path
    step_s: Number = Field(default=0.1, gt=0)

    @field_validator("bias", mode="before")
    @classmethod
    def _numeric_level_keys(cls, value: Any) -> Any:  # Any: pydantic validator input
        if isinstance(value, dict):
            return {_level_key(k): v for k, v in value.items()}
        return value

    def bias_for(self, row: TrialRow) -> float:
        """The population bias in trial ``row``."""
        if not isinstance(self.bias, dict):
            return float(self.bias)
        assert self.factor is not None
        return float(self.bias[_level_key(row.get(f"{self.factor}_interval1", row[self.factor]))])

    def participant_draws(self, rng: np.random.Generator) -> dict[str, float]:
        sd = float(self.between_subject_sd)
        return {"offset": float(rng.normal(0.0, sd)) if sd > 0 else 0.0}

    def final(self, row: TrialRow, participant: Mapping[str, float], u: float) -> float:
        """The trial's final setting from its uniform ``u`` in [0, 1) (u = 0 read as the smallest draw above 0)."""
        z = NormalDist().inv_cdf(min(max(u, 2.0 ** -53), 1.0 - 2.0 ** -53))
        variable = str(row[ADJUSTMENT_VARIABLE_COLUMN])
        value = float(row[reference_column(variable)]) + self.bias_for(row) + participant["offset"] + float(self.sd) * z
        return _clip(value, float(row[f"{variable}_min"]), float(row[f"{variable}_max"]))

    def answer(self, row: TrialRow, participant: Mapping[str, float], u: float) -> str:
        return repr(self.final(row, participant, u))

    def extras(self, row: TrialRow, participant: Mapping[str, float], u: float) -> dict[str, float | str]:
        """The path: from the start one step every ``step_s`` towards the final value, ending on it."""
        variable = str(row[ADJUSTMENT_VARIABLE_COLUMN])
        start, final = float(row[start_column(variable)]), self.final(row, participant, u)
        step = float(row[f"{variable}_step"])
        n = math.ceil(abs(final - start) / step - 1e-9)
        sign = 1.0 if final >= start else -1.0
        path = [(k * float(self.step_s), start + sign * k * step) for k in range(n)] + [(n * float(self.step_s), final)]
        return {path_column(variable): path_json(path if n else [(0.0, start)])}


#: the schedule column naming the adjusted variable (what the simulated observer and the analysis read)
ADJUSTMENT_VARIABLE_COLUMN = "adjustment_variable"

#: keys: arrows, +/- (and = for +, unshifted), the keypad's; Enter, the keypad's Enter or space confirm
_KEYS = {"up": UP, "down": DOWN, "right": UP, "left": DOWN, "+": UP, "=": UP, "-": DOWN, "kp_add": UP,
         "kp_subtract": DOWN, "enter": CONFIRM, "kp_enter": CONFIRM, "space": CONFIRM}
#: response-box buttons: U / D / C, or 1 (up), 2 (down), 3 (confirm)
_BUTTONS = {"U": UP, "D": DOWN, "C": CONFIRM, "1": UP, "2": DOWN, "3": CONFIRM}


def _field_value(item: object, dotted: str) -> tuple[bool, object]:
    """The value of ``item``'s field ``dotted`` (``depth``, ``surface.contrast``, ``centre_deg.0``): (found, value)."""
    value: object = item
    for part in dotted.split("."):
        if isinstance(value, (list, tuple)) and part.isdigit() and int(part) < len(value):
            value = value[int(part)]
        elif not isinstance(value, (list, tuple)) and part in getattr(type(value), "model_fields", {}):
            value = getattr(value, part)
        else:
            return False, None
    return True, value


def _reads(value: object, variable: str) -> bool:
    """Whether a field's value reads ``variable`` (``{factor: NAME}`` or a depth's factor)."""
    if isinstance(value, FactorRef):
        return value.factor == variable
    if isinstance(value, Depth):
        return variable in value.factor_names
    return False


class Adjustment(ResponseKindSpec):
    name = "adjustment"
    label = "method of adjustment"
    model = AdjustmentResponse
    observer_models = (AdjustmentObserver,)
    keys = _KEYS
    buttons = _BUTTONS
    #: controllers: either stick adjusts continuously (its forward deflection), either select button confirms
    #: (psyop.devices.xr.tracking: the raw names "thumbstick", "left", "right")
    controller: ClassVar[Mapping[str, str]] = {"thumbstick": AXIS, "left": CONFIRM, "right": CONFIRM}
    fields = {"AdjustmentResponse": {"kind": "plan", "question": "plan", "variable": "kinds", "item": "kinds",
                                     "field": "kinds", "stimulus": "kinds", "start": "kinds", "bounds": "kinds",
                                     "step": "kinds", "rate_per_s": "kinds", "reference": "kinds"},
              "UniformStart": {"uniform": "kinds"},
              "Bounds": {"min": "kinds", "max": "kinds"},
              "AdjustmentObserver": {k: "kinds" for k in ("kind", "factor", "bias", "sd", "between_subject_sd",
                                                          "step_s")}}

    def columns(self, response: KindResponse, schedule: ScheduleInput) -> dict[str, np.ndarray]:
        """The interval's mode and overrides; the start (the variable's column and ``<variable>_start``, drawn
        from the kind's stream for a uniform start), the reference, the bounds and step, and the empty path."""
        assert isinstance(response, AdjustmentResponse)
        columns, n, variable = schedule.columns, schedule.n, response.variable
        out: dict[str, np.ndarray] = {"mode_interval1": mode_values(response.stimulus.mode, columns, n)}
        for name in sorted(response.stimulus.set):
            out[f"{name}_interval1"] = np.full(n, response.stimulus.set[name], dtype=np.float64)
        start = response.start
        if isinstance(start, UniformStart):
            low, high = (float(v) for v in start.uniform)
            starts = schedule.rng.uniform(low, high, size=n)
        elif isinstance(start, FactorRef):
            starts = np.asarray(columns[start.factor], dtype=np.float64)
        else:
            starts = np.full(n, float(start), dtype=np.float64)
        reference = response.reference
        out[variable] = starts.astype(np.float64)
        out[start_column(variable)] = starts.astype(np.float64)
        out[reference_column(variable)] = (np.asarray(columns[reference.factor], dtype=np.float64)
                                           if isinstance(reference, FactorRef) else
                                           np.full(n, float(reference), dtype=np.float64))
        out[f"{variable}_min"] = np.full(n, float(response.bounds.min))
        out[f"{variable}_max"] = np.full(n, float(response.bounds.max))
        out[f"{variable}_step"] = np.full(n, float(response.step))
        out[ADJUSTMENT_VARIABLE_COLUMN] = np.full(n, variable, dtype=object)
        out[path_column(variable)] = np.full(n, "", dtype=object)
        return out

    def check(self, response: KindResponse, checks: Checks, path: Loc) -> None:
        """The item exists and its field reads the variable; min < max; the start (every value it can take) and a
        numeric reference... lie within the bounds; the variable is no design factor and says its unit."""
        assert isinstance(response, AdjustmentResponse)
        variable, low, high = response.variable, float(response.bounds.min), float(response.bounds.max)
        if not has_unit_suffix(variable):
            checks.add(path + ("variable",), f"the adjusted variable '{variable}' must say its unit in its name "
                                             "(e.g. match_D for a depth in dioptres, size_deg for a size)")
        if variable in checks.factors:
            checks.add(path + ("variable",), f"'{variable}' is a factor of design.factors; the adjusted variable "
                                             "is the participant's, not the design's: give it a name of its own")
        items = {item.id: item for item in checks.p.scene}
        if response.item not in items:
            checks.add(path + ("item",), f"no scene item has id '{response.item}' (ids: {', '.join(items)})")
        else:
            found, value = _field_value(items[response.item], response.field)
            if not found:
                checks.add(path + ("field",), f"scene item '{response.item}' has no field '{response.field}' (a "
                                              "field such as depth, size_deg, surface.contrast or centre_deg.0)")
            elif not _reads(value, variable):
                checks.add(path + ("field",), f"'{response.item}.{response.field}' does not read the adjusted "
                                              f"variable: write it as {{factor: {variable}}} in the scene")
        if not low < high:
            checks.add(path + ("bounds",), f"bounds min ({low:g}) must be less than max ({high:g})")
            return
        start = response.start
        if isinstance(start, UniformStart):
            a, b = (float(v) for v in start.uniform)
            if not a <= b:
                checks.add(path + ("start", "uniform"), f"the start range [{a:g}, {b:g}] is reversed; give [low, high]")
            elif a < low or b > high:
                checks.add(path + ("start", "uniform"), f"the start range [{a:g}, {b:g}] reaches outside the bounds "
                                                        f"[{low:g}, {high:g}]")
        elif isinstance(start, FactorRef):
            if checks.factor_exists(start.factor, path + ("start", "factor"), numeric=True):
                outside = [v for v in checks.factors[start.factor].all_levels() if not low <= float(v) <= high]
                if outside:
                    checks.add(path + ("start", "factor"), f"{start.factor} level {outside[0]:g} is outside the bounds "
                                                           f"[{low:g}, {high:g}]")
        elif not low <= float(start) <= high:
            checks.add(path + ("start",), f"the start {float(start):g} is outside the bounds [{low:g}, {high:g}]")
        if isinstance(response.reference, FactorRef):
            checks.factor_exists(response.reference.factor, path + ("reference", "factor"), numeric=True)
        for key in response.stimulus.set:
            if key == variable:
                checks.add(path + ("stimulus", "set", key), "the adjusted variable is the participant's; an interval "
                                                            "cannot set it")
            else:
                checks.factor_exists(key, path + ("stimulus", "set", key), numeric=True)
        if isinstance(response.stimulus.mode, ModeFromFactor):
            checks.mode_factor(response.stimulus.mode.factor, path + ("stimulus", "mode", "factor"))

    def check_observer(self, observer: ObserverBase, response: KindResponse, checks: Checks, path: Loc) -> None:
        """``bias`` is one number without a factor, else one per level of ``factor``."""
        assert isinstance(observer, AdjustmentObserver) and isinstance(response, AdjustmentResponse)
        bias = observer.bias
        if observer.factor is None:
            if isinstance(bias, dict):
                checks.add(path + ("bias",), "bias is given per level, but the observer names no factor; add "
                                             "factor: NAME (the factor whose levels these are)")
            return
        if not isinstance(bias, dict):
            checks.add(path + ("bias",), f"bias is one number, but the observer reads factor '{observer.factor}'; "
                                         "give one bias per level (bias: {level: value}) or leave factor out")
            return
        if not checks.factor_exists(observer.factor, path + ("factor",)):
            return
        levels = [_level_key(level) for level in checks.factors[observer.factor].all_levels()]
        for level in levels:
            if level not in bias:
                checks.add(path + ("bias",), f"no bias for {observer.factor} level '{level}'; add '{level}: <bias>'")
        for key in bias:
            if key not in levels:
                checks.add(path + ("bias", key), f"'{key}' is not a level of {observer.factor} ({', '.join(levels)})")

    def score(self, row: TrialRow, answer: str) -> Scored:
        return Scored(correct=None)

    def targets(self, study: StudyInputs) -> list[AnalysisTarget]:
        """PSE, bias and SD per condition, the ANOVA in results/ and their figure (analysis/adjustment.py)."""
        return [figure_target(study, "adjustment", "analysis/adjustment.py")]


KIND = Adjustment()
