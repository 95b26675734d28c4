"""Adaptive levels in a session: the protocol's ``adaptive:`` factor -> one procedure per condition.

Before each trial the session asks :meth:`AdaptiveLevels.fill` for the row's level: the
condition's procedure is rebuilt from that condition's logged history (non-practice trials with
an answer, in trial order) and its ``next_level`` goes into the level column (and into the
``<level>_interval1/2`` columns where the response sets a fixed reference level). After the
response, :meth:`AdaptiveLevels.complete` adds the procedure's state after this trial to the
record; only once the record is durable does :meth:`AdaptiveLevels.commit` add it to the history.
A resumed session starts from the logged trials (:meth:`AdaptiveLevels.from_log`), so after a
crash the next level is exactly what an uninterrupted session would have chosen: there is no
procedure state to save or lose.

Logged per trial (``U`` = the level factor's unit suffix, e.g. ``D``):
``adaptive_procedure`` (e.g. ``quest_plus``, ``staircase_1u3d``) and ``adaptive_trials`` (this
condition's counted trials before this one: the history the level came from); then, after this
trial's response: ``adaptive_step_U`` and ``adaptive_reversals`` (the staircase's step for its next
change and its reversals so far; NaN and 0 for QUEST+), ``adaptive_estimate_U`` and
``adaptive_estimate_sd_U`` (the running threshold estimate: QUEST+ posterior mean/SD; staircase
reversal mean and its standard error, inf before two reversals). The last counted trial of a
condition holds the procedure's final estimate.

Stopping (``target_sd``): before each trial :meth:`AdaptiveLevels.stopped` asks the condition's
procedure, rebuilt from the log, whether it has finished; if so the trial is not run and not
logged (it is absent from the trial log). :meth:`AdaptiveLevels.stop_summary` says, per
condition, why it stopped and how many scheduled trials were not run; session.json records it as
``adaptive_stop`` and the completeness check counts those trials as done. Because the decision
is a function of the logged trials only, a resumed session skips exactly the trials an
uninterrupted one skips.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from psyop.adaptive.history import Observation
from psyop.adaptive.procedure import Procedure, make_procedure
from psyop.adaptive.quest_plus import QuestPlusSpec
from psyop.adaptive.staircase import StaircaseSpec, exact_decimal
from psyop.adaptive.state import ProcedureState
from psyop.adaptive.stopping import StopRule
from psyop.records import JsonObject, TrialRow

if TYPE_CHECKING:
    from psyop.protocol.model import Protocol

_RULES = {"1u2d": (1, 2), "1u3d": (1, 3)}


@dataclass(frozen=True)
class AdaptivePlan:
    """What the session runs for the protocol's adaptive factor."""

    factor: str
    spec: QuestPlusSpec | StaircaseSpec
    test_level: float | None  # response.test.set[factor], if the test interval has a fixed level
    reference_level: float | None  # response.reference.set[factor], e.g. 0 for discrimination

    @property
    def unit(self) -> str:
        return self.factor.rsplit("_", 1)[-1]

    def log_columns(self) -> JsonObject:
        """The per-trial log columns and their empty schedule values (they fix the log's types)."""
        u = self.unit
        return {"adaptive_procedure": "", "adaptive_trials": np.int64(-1), f"adaptive_step_{u}": math.nan,
                "adaptive_reversals": np.int64(0), f"adaptive_estimate_{u}": math.nan,
                f"adaptive_estimate_sd_{u}": math.nan}


def adaptive_plan(protocol: "Protocol") -> AdaptivePlan | None:
    """The plan of the protocol's adaptive factor (validated by psyop.protocol.semantics), or None."""
    for name, factor in protocol.design.factors.items():
        a = factor.adaptive
        if a is None:
            continue
        stop = StopRule(max_trials=int(protocol.design.repetitions),
                        target_sd=None if a.target_sd is None else float(a.target_sd),
                        min_trials=int(a.min_trials or 1))
        if a.procedure == "quest_plus":
            points = int(a.grid_points or 101)
            spec: QuestPlusSpec | StaircaseSpec = QuestPlusSpec.default(
                float(a.min), float(a.max), stop=stop, stimulus_count=points, threshold_count=points,
                first_level=float(a.start))
        elif a.procedure == "staircase":
            # the default steps from the exact decimal range (0.1 to 1.3 is 1.2, not 1.2000000000000002)
            span = exact_decimal(float(a.max)) - exact_decimal(float(a.min))
            steps = (tuple(float(s) for s in a.step_sizes) if a.step_sizes
                     else tuple(float(span / n) for n in (10, 20, 40)))
            rule = a.rule or "1u3d"
            up, down = _RULES.get(rule, (1, 1))
            spec = StaircaseSpec(start=float(a.start), min=float(a.min), max=float(a.max),
                                 rule="weighted" if rule == "weighted" else "transformed", up=up, down=down,
                                 target=float(a.target) if a.target is not None else 0.75, step_sizes=steps,
                                 stop_reversals=None, stop=stop)
        else:  # semantics refuses other names; reaching here is a programming error
            raise ValueError(f"unknown adaptive procedure {a.procedure!r}")
        response = protocol.response
        test_set = getattr(getattr(response, "test", None), "set", {}) or {}
        ref_set = getattr(getattr(response, "reference", None), "set", {}) or {}
        return AdaptivePlan(name, spec, _maybe_float(test_set.get(name)), _maybe_float(ref_set.get(name)))
    return None


def row_at_level(plan: AdaptivePlan, row: TrialRow, level: float) -> JsonObject:
    """``row`` with the adaptive factor at ``level``: its column and each interval's copy of it (an
    interval whose ``set:`` fixes the factor keeps that value). The session fills each trial this
    way; ``psyop render --level`` and ``psyop audit`` preview levels with it."""
    out = dict(row)
    out[plan.factor] = float(level)
    for k in (1, 2):
        column = f"{plan.factor}_interval{k}"
        if column in out:
            is_test = int(out.get("correct_interval", 1)) == k
            fixed = plan.test_level if is_test else plan.reference_level
            out[column] = float(level) if fixed is None else fixed
    return out


def preview_levels(protocol: "Protocol", given: tuple[float, ...] = ()) -> tuple[float, ...]:
    """The adaptive factor's levels to preview: ``given`` (each checked against [min, max]), else the
    range's min, start and max. Empty when the protocol has no adaptive factor (``given`` is then an error).

    Examples
    --------
    >>> from psyop.protocol import load_protocol
    >>> preview_levels(load_protocol("protocols/examples/detection_quest_plus.yaml"))
    (0.0, 0.5, 1.5)
    """
    from psyop.errors import UserError

    adaptive = [(name, f.adaptive) for name, f in protocol.design.factors.items() if f.adaptive is not None]
    if not adaptive:
        if given:
            raise UserError("--level previews an adaptive factor, and this protocol has none; its levels are fixed "
                            "(pick a trial with --trial)", "--level")
        return ()
    name, a = adaptive[0]
    for level in given:
        if not (math.isfinite(level) and float(a.min) <= level <= float(a.max)):
            raise UserError(f"--level {level:g} is outside {name}'s adaptive range [{float(a.min):g}, {float(a.max):g}]",
                            "--level")
    if given:
        return tuple(float(v) for v in given)
    return tuple(sorted({float(a.min), float(a.start), float(a.max)}))


def _maybe_float(value: float | None) -> float | None:
    return None if value is None else float(value)


def add_log_columns(schedule: pd.DataFrame, plan: AdaptivePlan) -> pd.DataFrame:
    out = schedule.copy()
    for name, value in plan.log_columns().items():
        out[name] = pd.Series([value] * len(out), index=out.index,
                              dtype=object if isinstance(value, str) else type(value))
    return out


def _counts(row: TrialRow, factor: str) -> bool:
    """A trial the procedure learns from: not practice, answered, with a finite level."""
    correct = row.get("correct")
    if bool(row.get("practice", False)) or correct is None or (isinstance(correct, float) and math.isnan(correct)):
        return False
    level = row.get(factor)
    return level is not None and math.isfinite(float(level))


class AdaptiveLevels:
    """The session's adaptive levels (see the module docstring)."""

    def __init__(self, plan: AdaptivePlan) -> None:
        self.plan = plan
        self.procedure: Procedure = make_procedure(plan.spec)
        self.history: dict[str, list[Observation]] = {}
        self._states: dict[tuple[str, int], ProcedureState] = {}  # (condition, counted trials): a history only grows

    @classmethod
    def from_log(cls, plan: AdaptivePlan, logged: pd.DataFrame | None) -> "AdaptiveLevels":
        levels = cls(plan)
        if logged is not None and len(logged):
            for row in logged.sort_values("trial").to_dict("records"):
                levels.commit(row)
        return levels

    def state(self, condition: str) -> ProcedureState:
        history = self.history.get(condition, [])
        key = (condition, len(history))
        if key not in self._states:
            self._states[key] = self.procedure.state(history)
        return self._states[key]

    def fill(self, row: TrialRow) -> JsonObject:
        """``row`` with the level the condition's procedure chooses now."""
        state = self.state(str(row["condition"]))
        out = row_at_level(self.plan, row, float(state.next_level))
        out.update(adaptive_procedure=state.procedure, adaptive_trials=np.int64(state.trials))
        return out

    def complete(self, record: TrialRow) -> JsonObject:
        """``record`` with the running estimate after this trial (before it is made durable)."""
        out = dict(record)
        history = list(self.history.get(str(record["condition"]), []))
        if _counts(record, self.plan.factor):
            history.append(Observation(float(record[self.plan.factor]), bool(record["correct"])))
        state = self.procedure.state(history)
        self._states[(str(record["condition"]), len(history))] = state  # the state once committed
        out[f"adaptive_estimate_{self.plan.unit}"] = float(state.estimate_mean)
        out[f"adaptive_estimate_sd_{self.plan.unit}"] = float(state.estimate_sd)
        out["adaptive_reversals"] = np.int64(state.reversals)
        out[f"adaptive_step_{self.plan.unit}"] = float(state.step)
        return out

    def commit(self, record: TrialRow) -> None:
        """Add a durable trial to its condition's history."""
        if _counts(record, self.plan.factor):
            self.history.setdefault(str(record["condition"]), []).append(
                Observation(float(record[self.plan.factor]), bool(record["correct"])))

    def stopped(self, row: TrialRow) -> bool:
        """Whether ``row``'s condition has met its stop rule, so the (non-practice) trial is not run."""
        if bool(row.get("practice", False)):
            return False
        return self.state(str(row["condition"])).finished

    def stop_summary(self, schedule: pd.DataFrame, recorded: set[int]) -> JsonObject:
        """Per condition that has stopped: why, after how many counted trials, its estimate, and
        which of its scheduled trials are not run; plus their count (session.json's
        ``adaptive_stop``)."""
        u = self.plan.unit
        conditions: JsonObject = {}
        not_run = 0
        for condition, rows in schedule.groupby(schedule["condition"].astype(str), sort=True):
            state = self.state(str(condition))
            if not state.finished:
                continue
            practice = rows["practice"].astype(bool) if "practice" in rows else pd.Series(False, index=rows.index)
            trials = rows["trial"].astype(int)
            skipped = sorted(int(t) for t in trials[~trials.isin(recorded) & ~practice])
            not_run += len(skipped)
            conditions[str(condition)] = {"reason": state.stop_reason, "trials": int(state.trials),
                                          f"estimate_{u}": float(state.estimate_mean),
                                          f"estimate_sd_{u}": float(state.estimate_sd), "trials_not_run": skipped}
        return {"target_sd": self.plan.spec.stop.target_sd, "max_trials": self.plan.spec.stop.max_trials,
                "conditions": conditions, "n_trials_not_run": not_run}
