"""``left_right_nearer``: which side of a border looked nearer (ordinal depth). Columns ``mode``,
``near_side`` and the separation factor; accuracy per mode and separation."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Annotated, ClassVar, Literal, TypeGuard

import numpy as np
from pydantic import Field, PrivateAttr

from psyop.errors import UserError
from psyop.protocol.base import Number
from psyop.protocol.kinds.base import (AnalysisTarget, Checks, Counterbalance, KindResponse, ModeFromFactor,
                                       ObserverBase, ResponseKindSpec, ScheduleInput, Scored, StudyInputs,
                                       figure_target, mode_factor_of)
from psyop.protocol.kinds.modes import mode_values
from psyop.protocol.image_observer import ImageObserver, unread_fields
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
    declared: ClassVar[bool] = True
    #: the response's separation factor, the column p_correct's separations are read from (the plan passes it)
    _separation_column: str = PrivateAttr(default="separation_D")

    @classmethod
    def for_session(cls, params: Mapping[str, object]) -> "OrdinalAccuracy":
        """The model, reading separations from the plan's ``separation_column`` (the response's separation factor)."""
        model = cls.model_validate({k: v for k, v in params.items() if k in cls.model_fields})
        model._separation_column = str(params.get("separation_column") or "separation_D")
        return model

    def participant_draws(self, rng: np.random.Generator) -> dict[str, float]:
        """The participant's shift of every p, ``participant_shift`` ~ N(0, between_subject_sd)."""
        sd = float(self.between_subject_sd)
        return {"participant_shift": float(rng.normal(0.0, sd)) if sd > 0 else 0.0}

    def probability(self, row: TrialRow, participant: Mapping[str, float]) -> float:
        """p(correct) of the trial's mode and separation (separations equal to 6 decimals), shifted by the
        participant's draw and clipped to [0, 1]."""
        mode, separation = str(row["mode"]), round(float(row[self._separation_column]), 6)
        given = [p for named, by_separation in self.p_correct.items() if named == mode
                 for sep, p in by_separation.items() if round(float(sep), 6) == separation]
        if not given:
            raise UserError(f"observer: no p_correct for mode={mode!r}, separation_D={separation}", "protocol observer")
        return float(np.clip(float(given[-1]) + participant["participant_shift"], 0.0, 1.0))

    def answer(self, row: TrialRow, participant: Mapping[str, float], u: float) -> str:
        """The near side when ``u < p``, else the other side."""
        near = str(row["near_side"])
        return near if u < self.probability(row, participant) else ("left" if near == "right" else "right")


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
    takes_confidence = True  # one discrete choice: a confidence rating may follow
    model = LeftRightNearerResponse
    observer_models = (OrdinalAccuracy, ImageObserver)
    keys = {"left": "left", "right": "right", "l": "left", "r": "right"}
    buttons = {"L": "left", "R": "right", "1": "left", "2": "right"}
    controller = {"left": "left", "right": "right"}
    fields = {"LeftRightNearerResponse": {"kind": "plan", "question": "plan", "mode": "kinds",
                                          "separation_factor": "plan", "near_side": "kinds"},
              "OrdinalAccuracy": {"kind": "kinds", "p_correct": "kinds", "between_subject_sd": "kinds"},
              "ImageObserver": {k: "image_observer" for k in ImageObserver.model_fields if k != "eye"}}

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
        """p_correct must give a probability for every (mode, separation) a trial can have; the image observer
        takes only the fields its ordinal rule reads."""
        if isinstance(observer, ImageObserver):  # answers from the frames: nothing of the schedule to check
            for name in unread_fields(observer, self.name):
                checks.add(path + (name,), f"the image observer's left/right-nearer rule does not read {name}; "
                                           "remove it")
            return
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
