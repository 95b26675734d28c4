"""Transformed and weighted up-down staircases as pure functions of the history.

- Transformed (Levitt 1971): ``up``-up-``down``-down. After ``down`` correct responses in a row
  the level goes down one step; after ``up`` wrong responses in a row it goes up one step. 1-up-2-down
  converges on 70.7 % correct, 1-up-3-down on 79.4 %.
- Weighted (Kaernbach 1991): 1-up-1-down with unequal steps. Down by ``step`` after a correct
  response, up by ``step * target / (1 - target)`` after a wrong one; converges on ``target``
  (0.75: up steps three times the down steps).

Step rule: the step is ``step_sizes[min(reversals, len - 1)]`` (e.g. halve after the first and
second reversal). A reversal is a change of direction between two consecutive level changes; the
reversal level is the level of the trial that triggered the new direction. Levels are clamped to
[min, max]. Stopping: ``stop_reversals`` reversals, or the common :class:`StopRule`.

Exact grid: the walk runs in exact rational arithmetic on the decimal values the spec gives
(``0.1`` is 1/10, not the float nearest it), so every level is ``min + k * grain`` for an integer
k, where ``grain`` is the largest step that divides every step size (and, weighted, every up
step), ``start - min`` and ``max - min`` (:attr:`StaircaseSpec.grain`). A level is the float
nearest that exact value: 0.4 is ``0.4``, never ``0.4000000000000001``, and 0 is ``0.0``, never
``5.55e-17``, so levels group exactly. A logged level read back from a history is put on the grid
point it stands for (the nearest one; a level more than ``1e-9`` away from every grid point is
taken as it is).

Running estimate (calibrated; benchmarks/bench_adaptive_calibration.py, docs/adaptive.md): the
posterior mean and SD of the threshold (the 75 % point without lapse) given the staircase's own
trials, under QUEST+'s model and default prior over [min, max] (``QuestPlus.threshold_estimate``
on a stimulus grid of the staircase's levels). The mean of the reversal levels +- its standard
error, the textbook estimate, estimates the rule's convergence point (79.4 % for 1-up-3-down, not
the 75 % threshold) and its SE ignores that successive reversals are correlated: over 500 held-out
observers its 95 % intervals covered the threshold far less often than 95 % (the benchmark's table).
The reversal mean is still reported (``ProcedureState.reversal_mean``); the estimate, the SD and
the ``target_sd`` stop use the posterior.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction
from functools import reduce
from typing import Literal, Sequence

from psyop.adaptive.history import Observation
from psyop.adaptive.quest_plus import QuestPlus, QuestPlusSpec
from psyop.adaptive.state import ProcedureState
from psyop.adaptive.stopping import StopRule


@dataclass(frozen=True)
class StaircaseSpec:
    start: float
    min: float
    max: float
    rule: Literal["transformed", "weighted"] = "transformed"
    up: int = 1
    down: int = 3
    target: float = 0.75  # weighted only
    step_sizes: tuple[float, ...] = (0.2, 0.1, 0.05)
    stop_reversals: int | None = 12
    discard_reversals: int = 2
    estimate_reversals: int | None = None  # None: every reversal after the discarded ones
    stop: StopRule = field(default_factory=lambda: StopRule(max_trials=200))

    def __post_init__(self) -> None:
        object.__setattr__(self, "step_sizes", tuple(float(s) for s in self.step_sizes))
        if not self.min <= self.start <= self.max or not self.min < self.max:
            raise ValueError(f"need min <= start <= max and min < max, got {self.min}, {self.start}, {self.max}")
        if self.rule not in ("transformed", "weighted"):
            raise ValueError(f"rule must be 'transformed' or 'weighted', got {self.rule!r}")
        if self.up < 1 or self.down < 1:
            raise ValueError("up and down must be >= 1")
        if not 0.5 <= self.target < 1:
            raise ValueError(f"target must be in [0.5, 1), got {self.target}")
        if not self.step_sizes or not all(s > 0 for s in self.step_sizes):
            raise ValueError("step_sizes: need at least one step, all > 0")
        if self.stop_reversals is not None and self.stop_reversals < 1:
            raise ValueError("stop_reversals must be >= 1")
        if self.discard_reversals < 0 or (self.estimate_reversals is not None and self.estimate_reversals < 1):
            raise ValueError("discard_reversals must be >= 0 and estimate_reversals >= 1")

    @property
    def grain(self) -> Fraction:
        """The grid step: every level is ``min + k * grain`` exactly (module docstring).

        Examples
        --------
        >>> StaircaseSpec(start=0.8, min=0.0, max=1.5, step_sizes=(0.2, 0.1, 0.05)).grain
        Fraction(1, 20)
        """
        steps = [exact_decimal(s) for s in self.step_sizes]
        if self.rule == "weighted":
            ratio = exact_decimal(self.target) / (1 - exact_decimal(self.target))
            steps += [s * ratio for s in steps]
        low = exact_decimal(self.min)
        parts = steps + [exact_decimal(self.start) - low, exact_decimal(self.max) - low]
        return reduce(_gcd, [p for p in parts if p != 0])

    def grid_level(self, k: int) -> float:
        """The float of grid level ``min + k * grain``."""
        return float(exact_decimal(self.min) + k * self.grain)

    def on_grid(self, level: float) -> bool:
        """True when ``level`` is exactly (as a float) a grid level within [min, max].

        Examples
        --------
        >>> spec = StaircaseSpec(start=0.8, min=0.0, max=1.5, step_sizes=(0.2, 0.1))
        >>> spec.on_grid(0.4), spec.on_grid(0.4000000000000001), spec.on_grid(5.55e-17)
        (True, False, False)
        """
        k = round((Fraction(level) - exact_decimal(self.min)) / self.grain)
        return float(level) == self.grid_level(k) and float(self.min) <= float(level) <= float(self.max)

    @property
    def name(self) -> str:
        if self.rule == "weighted":
            return f"staircase_weighted_{self.target:g}"
        return f"staircase_{self.up}u{self.down}d"


def exact_decimal(x: float) -> Fraction:
    """The exact value a float stands for: the decimal of its shortest repr (0.1 -> 1/10).

    Examples
    --------
    >>> exact_decimal(0.1)
    Fraction(1, 10)
    """
    return Fraction(repr(float(x)))


def _gcd(a: Fraction, b: Fraction) -> Fraction:
    return Fraction(math.gcd(a.numerator * b.denominator, b.numerator * a.denominator), a.denominator * b.denominator)


class Staircase:
    """A staircase over a :class:`StaircaseSpec`; every answer is a function of the history."""

    def __init__(self, spec: StaircaseSpec) -> None:
        self.spec = spec
        self.name = spec.name
        # the walk runs on integers k of the grain: level = min + k * grain, exactly
        self._low = exact_decimal(spec.min)
        self._grain = spec.grain
        self._top = int((exact_decimal(spec.max) - self._low) / self._grain)
        self._start = int((exact_decimal(spec.start) - self._low) / self._grain)
        self._steps = [int(exact_decimal(x) / self._grain) for x in spec.step_sizes]
        ratio = exact_decimal(spec.target) / (1 - exact_decimal(spec.target))
        self._up_steps = [int(exact_decimal(x) * ratio / self._grain) if spec.rule == "weighted" else k
                          for x, k in zip(spec.step_sizes, self._steps)]
        self._grain_float = float(self._grain)
        self._levels: dict[int, float] = {}
        self._estimator: QuestPlus | None = None

    #: the most grid levels the estimator's stimulus grid takes one by one (else levels go through
    #: QUEST+'s exact off-grid likelihood)
    MAX_ESTIMATOR_LEVELS = 2001

    def estimator(self) -> QuestPlus:
        """The posterior behind the estimate: QUEST+'s default threshold, width and lapse grids over
        [min, max], its stimulus grid the staircase's own levels."""
        if self._estimator is None:
            low, high = float(self.spec.min), float(self.spec.max)
            default = QuestPlusSpec.default(low, high)
            stimulus = (tuple(self._level(k) for k in range(self._top + 1))
                        if self._top + 1 <= self.MAX_ESTIMATOR_LEVELS else default.stimulus)
            self._estimator = QuestPlus(QuestPlusSpec(stimulus=stimulus, threshold=default.threshold,
                                                      width=default.width, lapse=default.lapse))
        return self._estimator

    def next_level(self, history: Sequence[Observation]) -> float:
        """Where the next trial goes (the walk only, without the estimate)."""
        return self._walk(history)[0]

    def _level(self, k: int) -> float:
        """The float of grid level k (the float nearest ``min + k * grain``)."""
        if k not in self._levels:
            self._levels[k] = float(self._low + k * self._grain)
        return self._levels[k]

    def _snap(self, level: float) -> int | None:
        """The grid index a logged level stands for, or None when it is no grid level (module docstring)."""
        k = round((level - float(self._low)) / self._grain_float)
        return k if abs(self._level(k) - level) <= 1e-9 else None

    def _walk(self, history: Sequence[Observation]) -> tuple[float, list[float], float]:
        """Replay on the grid: (next level, reversal levels, current step)."""
        spec = self.spec
        steps, up_steps = self._steps, self._up_steps
        k: int | float = self._start
        reversals: list[int | float] = []
        last_direction = 0
        run_correct = run_wrong = 0
        for obs in history:
            i = min(len(reversals), len(steps) - 1)
            snapped = self._snap(obs.level)
            # a level from elsewhere (no grid level): walk on from it in grain units, off the grid
            shown: int | float = snapped if snapped is not None else \
                float((Fraction(obs.level) - self._low) / self._grain)
            direction = 0
            if spec.rule == "weighted":
                direction = -1 if obs.correct else 1
                delta = steps[i] if obs.correct else up_steps[i]
            else:
                if obs.correct:
                    run_correct, run_wrong = run_correct + 1, 0
                    if run_correct >= spec.down:
                        direction, run_correct = -1, 0
                else:
                    run_correct, run_wrong = 0, run_wrong + 1
                    if run_wrong >= spec.up:
                        direction, run_wrong = 1, 0
                delta = steps[i]
            if direction == 0:
                k = shown
                continue
            if last_direction != 0 and direction != last_direction:
                reversals.append(shown)
            last_direction = direction
            k = min(max(shown + direction * delta, 0), self._top)
        step = float(self._grain * steps[min(len(reversals), len(steps) - 1)])
        return self._value(k), [self._value(r) for r in reversals], step

    def _value(self, k: int | float) -> float:
        return self._level(k) if isinstance(k, int) else float(self._low + Fraction(k) * self._grain)

    def state(self, history: Sequence[Observation]) -> ProcedureState:
        spec = self.spec
        level, reversals, step = self._walk(history)
        counted = reversals[spec.discard_reversals:]
        if spec.estimate_reversals is not None:
            counted = counted[-spec.estimate_reversals:]
        reversal_mean = sum(counted) / len(counted) if counted else math.nan
        mean, sd = self.estimator().threshold_estimate(history)
        reason = spec.stop.reason(len(history), sd)
        if not reason and spec.stop_reversals is not None and len(reversals) >= spec.stop_reversals:
            reason = "reversals"
        return ProcedureState(procedure=self.name, trials=len(history), next_level=level,
                              finished=bool(reason), stop_reason=reason, estimate_mean=mean,
                              estimate_sd=sd, step=step, reversals=len(reversals), reversal_mean=reversal_mean)
