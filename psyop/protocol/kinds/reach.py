"""``reach``: blind reach to the remembered target (egocentric distance). Columns ``rendering``,
``target_fraction`` and ``mode``; the answer is the hand's horizontal distance when the participant
confirms."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Annotated, ClassVar, Literal

import numpy as np
from pydantic import Field

from psyop.errors import UserError
from psyop.protocol.base import Number, StrictModel
from psyop.protocol.kinds.base import (AnalysisTarget, Checks, DrawnAnswer, KindResponse, ObserverBase,
                                       ResponseKindSpec, ScheduleInput, StudyInputs, figure_target)
from psyop.protocol.scene import ReachTarget, RenderingMode
from psyop.records import Loc, TrialRow


def _reach_modes() -> dict[str, RenderingMode]:
    """The reach response's default modes: rendering factor level -> rendering mode."""
    return {"enabled": "ocular", "disabled": "conventional"}


class ReachResponse(KindResponse):
    """Blind reach. ``modes`` maps each level of the rendering factor to a rendering mode."""

    kind: Literal["reach"]
    intervals_needed: ClassVar[int] = 1
    question: str = "Reach to where the target was, then pull the trigger."
    rendering_factor: str = "rendering"
    target_factor: str = "target_fraction"
    modes: dict[str, RenderingMode] = Field(default_factory=_reach_modes)
    average_last_samples: Annotated[int, Field(ge=1, le=10000)] = 10

    def factors_read(self) -> set[str]:
        """The rendering and target factors."""
        return {self.rendering_factor, self.target_factor}


#: where a simulated hand ends relative to the eyes (m, up positive): a reach target's default ``height_m``
HAND_HEIGHT_M: float = float(ReachTarget.model_fields["height_m"].default)


class ReachCondition(StrictModel):
    """reach_m = slope * target_m + intercept_m + N(0, noise_sd_m)."""

    slope: Number
    intercept_m: Number
    noise_sd_m: Number = Field(ge=0)


class Reach(ObserverBase):
    """Blind-reach model per rendering condition (keys: levels of the rendering factor): the hand's horizontal
    distance = intercept_m + slope * target_m + the participant's own deviations + N(0, noise_sd_m).

    ``target_m = target_fraction * arm_reach_m`` (the target's horizontal distance); each participant's arm reach
    deviates from ``arm_reach_m`` by N(0, ``arm_reach_sd_m``), and its line from the condition's by one draw of
    N(0, ``slope_sd``) and one of N(0, ``intercept_sd_m``) (shared by the conditions). The hand ends at
    :data:`HAND_HEIGHT_M` below the eyes, straight ahead, at most ``max_reach_fraction`` of the arm reach from
    the eyes (3-D) and never behind them; a hand tracker (the session's pose source) then measures it."""

    kind: Literal["reach"]
    arm_reach_m: Number = Field(gt=0.2, le=1.5)
    arm_reach_sd_m: Number = Field(default=0.0, ge=0)
    slope_sd: Number = Field(default=0.0, ge=0, le=1, description="sd of a participant's slope deviation (shared by conditions)")
    intercept_sd_m: Number = Field(default=0.0, ge=0, le=0.5, description="sd of a participant's intercept deviation")
    max_reach_fraction: Number = Field(default=1.0, gt=0.3, le=1.5,
                                       description="the hand ends at most this fraction of arm reach from the eyes")
    by_condition: dict[str, ReachCondition] = Field(min_length=1)
    declared: ClassVar[bool] = True
    draws_stream: ClassVar[bool] = True  # the trial's normal motor noise

    def participant_draws(self, rng: np.random.Generator) -> dict[str, float]:
        """The participant's ``arm_reach_m``, ``slope_offset`` and ``intercept_offset_m``, drawn in that order."""
        draws = {"arm_reach_m": float(self.arm_reach_m)}
        for key, sd in (("arm_reach_m", self.arm_reach_sd_m), ("slope_offset", self.slope_sd),
                        ("intercept_offset_m", self.intercept_sd_m)):
            draws[key] = draws.get(key, 0.0) + (float(rng.normal(0.0, float(sd))) if sd > 0 else 0.0)
        return draws

    def answer_drawn(self, row: TrialRow, participant: Mapping[str, float], rng: np.random.Generator) -> DrawnAnswer:
        """Where the hand really ends (``reach_m``, its horizontal distance, written to 6 decimals as the answer)
        and the hand's position, the arm reach and the target distance beside it."""
        rendering = str(row.get("rendering", ""))
        condition = self.by_condition.get(rendering)
        if condition is None:
            raise UserError(f"observer: no reach model for rendering {rendering!r}; add it under by_condition",
                            "protocol observer")
        arm_m = participant["arm_reach_m"]
        target_m = float(row["target_fraction"]) * arm_m
        reach_m = (float(condition.intercept_m) + participant["intercept_offset_m"]
                   + (float(condition.slope) + participant["slope_offset"]) * target_m
                   + float(rng.normal(0.0, float(condition.noise_sd_m))))
        max_reach_m = float(self.max_reach_fraction) * arm_m
        horizontal_max_m = math.sqrt(max(max_reach_m ** 2 - HAND_HEIGHT_M ** 2, 0.0))
        reach_m = min(max(reach_m, 0.0), horizontal_max_m)  # not behind the eyes, not beyond the arm
        return DrawnAnswer(f"{reach_m:.6f}", reach_m, {"arm_reach_m": arm_m, "target_m": target_m, "hand_x_m": 0.0,
                                                       "hand_y_m": HAND_HEIGHT_M, "hand_z_m": -reach_m})


class ReachKind(ResponseKindSpec):
    name = "reach"
    label = "reach"
    model = ReachResponse
    observer_models = (Reach,)
    keys = {"space": "confirm", "enter": "confirm"}
    controller = {"left": "confirm", "right": "confirm"}
    needs_hand_pose = True
    fields = {"ReachResponse": {"kind": "plan", "question": "plan", "rendering_factor": "kinds",
                                "target_factor": "kinds", "modes": "kinds", "average_last_samples": "plan"},
              "Reach": {k: "kinds" for k in ("kind", "arm_reach_m", "arm_reach_sd_m", "by_condition", "slope_sd",
                                             "intercept_sd_m", "max_reach_fraction")},
              "ReachCondition": {"slope": "kinds", "intercept_m": "kinds", "noise_sd_m": "kinds"}}

    def columns(self, response: KindResponse, schedule: ScheduleInput) -> dict[str, np.ndarray]:
        """The mode of each trial's rendering level, and the rendering/target columns under their standard names."""
        assert isinstance(response, ReachResponse)
        out: dict[str, np.ndarray] = {}
        rendering = schedule.columns[response.rendering_factor]
        mode = np.array([response.modes[str(r)] for r in rendering], dtype=object)
        out["mode"] = mode
        out["mode_interval1"] = mode
        if response.rendering_factor != "rendering":
            out["rendering"] = rendering
        if response.target_factor != "target_fraction":
            out["target_fraction"] = schedule.columns[response.target_factor]
        return out

    def check(self, response: KindResponse, checks: Checks, path: Loc) -> None:
        """Every level of the rendering factor has a mode; the target factor is numeric."""
        assert isinstance(response, ReachResponse)
        if checks.factor_exists(response.rendering_factor, path + ("rendering_factor",), numeric=False):
            for level in checks.factors[response.rendering_factor].all_levels():
                if level not in response.modes:
                    checks.add(path + ("modes",), f"rendering level '{level}' has no mode; add '{level}: ocular' "
                                                  "(or conventional/reversed) under modes")
        checks.factor_exists(response.target_factor, path + ("target_factor",), numeric=True)

    def check_observer(self, observer: ObserverBase, response: KindResponse, checks: Checks, path: Loc) -> None:
        assert isinstance(observer, Reach) and isinstance(response, ReachResponse)
        if response.rendering_factor in checks.factors:
            for level in checks.factors[response.rendering_factor].all_levels():
                if level not in observer.by_condition:
                    checks.add(path + ("by_condition",), f"no reach model for rendering '{level}'; add it")

    def targets(self, study: StudyInputs) -> list[AnalysisTarget]:
        return [figure_target(study, "reach", "analysis/fig_egocentric_reach.py")]


KIND = ReachKind()
