"""``left_right_nearer``: which side of a border looked nearer (ordinal depth). Columns ``mode``,
``near_side`` and the separation factor; accuracy per mode and separation."""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal, TypeGuard

import numpy as np
from pydantic import Field

from psyop.protocol.base import Number
from psyop.protocol.kinds.base import (AnalysisTarget, Checks, Counterbalance, KindResponse, ModeFromFactor,
                                       ObserverBase, ResponseKindSpec, ScheduleInput, Scored, StudyInputs,
                                       figure_target, mode_factor_of)
from psyop.protocol.kinds.modes import mode_values
from psyop.protocol.scene import RENDERING_MODES, RenderingMode, SinusoidalBorder
from psyop.records import Loc, TrialRow

Probability = Annotated[Number, Field(ge=0, le=1)]


class LeftRightNearerResponse(KindResponse):
    """Which side (left/right) of a border looked nearer."""

    kind: Literal["left_right_nearer"]
    intervals_needed: ClassVar[int] = 1
    question: str = "Which surface appeared nearer, left or right?"
    mode: RenderingMode | ModeFromFactor = ModeFromFactor(factor="mode")
    separation_factor: str = "separation_D"
    near_side: Counterbalance = "balanced"

    @property
    def counterbalance(self) -> Counterbalance:
        """How the near side is assigned."""
        return self.near_side

    def factors_read(self) -> set[str]:
        """The separation factor and the mode factor."""
        return {self.separation_factor} | mode_factor_of(self.mode)


class OrdinalAccuracy(ObserverBase):
    """p(correct) by rendering mode and separation: ``p_correct: {ocular: {1: 0.667, 2: 0.758}}``."""

    kind: Literal["ordinal_accuracy"]
    p_correct: dict[RenderingMode, dict[Number, Probability]] = Field(min_length=1)
    between_subject_sd: Number = Field(default=0.0, ge=0, le=0.5, description="sd of p across participants")


def _is_mode(name: str) -> TypeGuard[RenderingMode]:
    """``name`` is a rendering mode (a mode factor's level, checked by ``mode_factor``)."""
    return name in RENDERING_MODES


def _same(a: float | str, b: float | str) -> bool:
    if isinstance(a, str) or isinstance(b, str):
        return str(a) == str(b)
    return abs(float(a) - float(b)) <= 1e-9 * max(1.0, abs(float(a)))


class LeftRightNearer(ResponseKindSpec):
    name = "left_right_nearer"
    former_names = ("near_side",)
    label = "left/right nearer"
    model = LeftRightNearerResponse
    observer_models = (OrdinalAccuracy,)
    keys = {"left": "left", "right": "right", "l": "left", "r": "right"}
    buttons = {"L": "left", "R": "right", "1": "left", "2": "right"}
    controller = {"left": "left", "right": "right"}
    fields = {"LeftRightNearerResponse": {"kind": "plan", "question": "plan", "mode": "kinds",
                                          "separation_factor": "plan", "near_side": "kinds"},
              "OrdinalAccuracy": {"kind": "observer", "p_correct": "observer", "between_subject_sd": "observer"}}

    def columns(self, response: KindResponse, schedule: ScheduleInput) -> dict[str, np.ndarray]:
        assert isinstance(response, LeftRightNearerResponse)
        mode = mode_values(response.mode, schedule.columns, schedule.n)
        return {"mode": mode, "mode_interval1": mode,
                "near_side": np.where(schedule.binary, "right", "left").astype(object)}

    def check(self, response: KindResponse, checks: Checks, path: Loc) -> None:
        assert isinstance(response, LeftRightNearerResponse)
        if isinstance(response.mode, ModeFromFactor):
            checks.mode_factor(response.mode.factor, path + ("mode", "factor"))
        checks.factor_exists(response.separation_factor, path + ("separation_factor",), numeric=True)
        if not any(isinstance(item, SinusoidalBorder) and item.near_side == "schedule" for item in checks.p.scene):
            checks.add(path + ("near_side",), "the schedule draws each trial's near side, but no scene item reads it, so "
                                              "the same side would be nearer in every trial whatever the answer key "
                                              "says; add a sinusoidal_border with near_side: schedule (its default)")

    def check_observer(self, observer: ObserverBase, response: KindResponse, checks: Checks, path: Loc) -> None:
        """p_correct must give a probability for every (mode, separation) a trial can have."""
        assert isinstance(observer, OrdinalAccuracy) and isinstance(response, LeftRightNearerResponse)
        if isinstance(response.mode, ModeFromFactor):
            if response.mode.factor not in checks.factors:
                return
            modes = [str(m) for m in checks.factors[response.mode.factor].all_levels()]
        else:
            modes = [response.mode]
        if response.separation_factor not in checks.factors:
            return
        separations = checks.factors[response.separation_factor].all_levels()
        for mode in modes:
            given = observer.p_correct.get(mode) if _is_mode(mode) else None  # else: reported by mode_factor
            if given is None:
                checks.add(path + ("p_correct",), f"no p_correct for mode '{mode}'; add '{mode}: {{separation: p}}'")
                continue
            for separation in separations:
                if not any(_same(separation, key) for key in given):
                    checks.add(path + ("p_correct", mode), f"no p_correct for {response.separation_factor} = "
                                                           f"{separation} in mode '{mode}'; add '{separation}: p'")

    def score(self, row: TrialRow, answer: str) -> Scored:
        return Scored(correct=answer == str(row["near_side"]))

    def targets(self, study: StudyInputs) -> list[AnalysisTarget]:
        return [figure_target(study, "depth", "analysis/fig_ordinal_depth.py")]





KIND = LeftRightNearer()
