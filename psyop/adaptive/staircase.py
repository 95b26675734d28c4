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

Running estimate: the mean of the last ``estimate_reversals`` reversal levels after dropping the
first ``discard_reversals``; its SD is the standard error of that mean (sd / sqrt(n), n >= 2),
``inf`` before two usable reversals exist.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal, Sequence

from psyop.adaptive.history import Observation
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
    def name(self) -> str:
        if self.rule == "weighted":
            return f"staircase_weighted_{self.target:g}"
        return f"staircase_{self.up}u{self.down}d"


class Staircase:
    """A staircase over a :class:`StaircaseSpec`; every answer is a function of the history."""

    def __init__(self, spec: StaircaseSpec) -> None:
        self.spec = spec
        self.name = spec.name

    def _walk(self, history: Sequence[Observation]) -> tuple[float, list[float], float]:
        """Replay: (next level, reversal levels, current step)."""
        spec = self.spec
        level = float(spec.start)
        reversals: list[float] = []
        last_direction = 0
        run_correct = run_wrong = 0
        for obs in history:
            step = spec.step_sizes[min(len(reversals), len(spec.step_sizes) - 1)]
            shown = obs.level
            direction = 0
            if spec.rule == "weighted":
                direction = -1 if obs.correct else 1
                delta = step if obs.correct else step * spec.target / (1.0 - spec.target)
            else:
                if obs.correct:
                    run_correct, run_wrong = run_correct + 1, 0
                    if run_correct >= spec.down:
                        direction, run_correct = -1, 0
                else:
                    run_correct, run_wrong = 0, run_wrong + 1
                    if run_wrong >= spec.up:
                        direction, run_wrong = 1, 0
                delta = step
            if direction == 0:
                level = shown
                continue
            if last_direction != 0 and direction != last_direction:
                reversals.append(shown)
            last_direction = direction
            level = min(max(shown + direction * delta, spec.min), spec.max)
        step = spec.step_sizes[min(len(reversals), len(spec.step_sizes) - 1)]
        return level, reversals, step

    def state(self, history: Sequence[Observation]) -> ProcedureState:
        spec = self.spec
        level, reversals, step = self._walk(history)
        counted = reversals[spec.discard_reversals:]
        if spec.estimate_reversals is not None:
            counted = counted[-spec.estimate_reversals:]
        if len(counted) >= 2:
            mean = sum(counted) / len(counted)
            sd = math.sqrt(sum((r - mean) ** 2 for r in counted) / (len(counted) - 1) / len(counted))
        elif counted:
            mean, sd = counted[0], math.inf
        else:
            mean, sd = level, math.inf
        reason = spec.stop.reason(len(history), sd)
        if not reason and spec.stop_reversals is not None and len(reversals) >= spec.stop_reversals:
            reason = "reversals"
        return ProcedureState(procedure=self.name, trials=len(history), next_level=level,
                              finished=bool(reason), stop_reason=reason, estimate_mean=mean,
                              estimate_sd=sd, step=step, reversals=len(reversals))
