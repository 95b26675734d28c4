"""``reach``: blind reach to the remembered target (egocentric distance). Columns ``rendering``,
``target_fraction`` and ``mode``; the answer is the hand's horizontal distance when the participant
confirms."""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal

import numpy as np
from pydantic import Field

from psyop.protocol.base import Number, StrictModel
from psyop.protocol.kinds.base import (AnalysisTarget, Checks, KindResponse, ObserverBase, ResponseKindSpec,
                                       ScheduleInput, StudyInputs, figure_target)
from psyop.protocol.scene import RenderingMode
from psyop.records import Loc


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


class ReachCondition(StrictModel):
    """reach_m = slope * target_m + intercept_m + N(0, noise_sd_m)."""

    slope: Number
    intercept_m: Number
    noise_sd_m: Number = Field(ge=0)


class Reach(ObserverBase):
    """Blind-reach model per rendering condition (keys: levels of the rendering factor)."""

    kind: Literal["reach"]
    arm_reach_m: Number = Field(gt=0.2, le=1.5)
    arm_reach_sd_m: Number = Field(default=0.0, ge=0)
    slope_sd: Number = Field(default=0.0, ge=0, le=1, description="sd of a participant's slope deviation (shared by conditions)")
    intercept_sd_m: Number = Field(default=0.0, ge=0, le=0.5, description="sd of a participant's intercept deviation")
    max_reach_fraction: Number = Field(default=1.0, gt=0.3, le=1.5,
                                       description="the hand ends at most this fraction of arm reach from the eyes")
    by_condition: dict[str, ReachCondition] = Field(min_length=1)


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
              "Reach": {"kind": "observer", "arm_reach_m": "observer", "arm_reach_sd_m": "observer",
                        "by_condition": "observer", "slope_sd": "observer", "intercept_sd_m": "observer",
                        "max_reach_fraction": "observer"},
              "ReachCondition": {"slope": "observer", "intercept_m": "observer", "noise_sd_m": "observer"}}

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
