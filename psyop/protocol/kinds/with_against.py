"""``with_against``: did the scene move with the eye or against it (NC nulling, one interval; docs/protocols.md,
"NC calibration"). Columns ``mode`` (from the sign of the rendered NC) and ``rendered_nc_mm``."""

from __future__ import annotations

from typing import ClassVar, Literal

import numpy as np
from pydantic import Field

from psyop.protocol.base import Number
from psyop.protocol.kinds.base import (AnalysisTarget, Checks, KindResponse, ObserverBase, ProtocolParts,
                                       ResponseKindSpec, ScheduleInput, StudyInputs, figure_target)
from psyop.protocol.scene import FactorRef
from psyop.records import Loc


class WithAgainstResponse(KindResponse):
    """NC nulling: one interval rendered with the trial's signed NC (``display.rendering_nc`` with
    ``signed: true`` reading ``nc_factor``: > 0 ocular, 0 conventional, < 0 reversed); the participant answers
    whether the scene moved ``with`` the eye or ``against`` it."""

    kind: Literal["with_against"]
    intervals_needed: ClassVar[int] = 1
    question: str = "Did the scene move with your eye or against it?"
    nc_factor: str = "nc_mm"

    def factors_read(self) -> set[str]:
        """The signed NC factor."""
        return {self.nc_factor}


class NcNulling(ObserverBase):
    """An observer whose own NC is ``nc_mm`` (each simulated participant's drawn around it with sd
    ``between_subject_sd_mm``): p(against) = lapse + (1 - 2 lapse) * Phi((r - nc) / width_mm), r the signed NC
    the trial is rendered with (its camera's mode and NC rule); 'with' otherwise. Its point of subjective
    stability (p = 0.5) is its own NC."""

    kind: Literal["nc_nulling"]
    nc_mm: Number = Field(gt=0, lt=30, description="the observer's own NC, mm")
    width_mm: Number = Field(gt=0, le=30, description="sd of the cumulative normal, mm")
    lapse: Number = Field(default=0.0, ge=0, lt=0.5)
    between_subject_sd_mm: Number = Field(default=0.0, ge=0, le=10)


def with_against_columns(protocol: ProtocolParts, levels: np.ndarray) -> dict[str, np.ndarray]:
    """A nulling trial's mode from the sign of its NC level (> 0 ocular, 0 conventional, < 0 reversed) and
    ``rendered_nc_mm``, the signed NC it is rendered with in mm (a ``scale`` level times the eye model's NC)."""
    from psyop.protocol.display import resolve_eye_model

    levels = np.asarray(levels, dtype=np.float64)
    nc = protocol.display.rendering_nc
    scale_mm = resolve_eye_model(protocol.display).nc_m * 1000.0 if nc is not None and nc.scale is not None else 1.0
    mode = np.where(levels > 0, "ocular", np.where(levels < 0, "reversed", "conventional")).astype(object)
    return {"mode": mode, "mode_interval1": mode, "rendered_nc_mm": levels * scale_mm}


class WithAgainst(ResponseKindSpec):
    name = "with_against"
    label = "with/against (NC calibration)"
    model = WithAgainstResponse
    observer_models = (NcNulling,)
    keys = {"w": "with", "a": "against", "left": "with", "right": "against"}
    buttons = {"1": "with", "2": "against", "L": "with", "R": "against"}
    controller = {"left": "with", "right": "against"}
    fields = {"WithAgainstResponse": {"kind": "plan", "question": "plan", "nc_factor": "kinds"},
              "NcNulling": {k: "observer" for k in ("kind", "nc_mm", "width_mm", "lapse", "between_subject_sd_mm")}}

    def columns(self, response: KindResponse, schedule: ScheduleInput) -> dict[str, np.ndarray]:
        assert isinstance(response, WithAgainstResponse)
        return with_against_columns(schedule.protocol, np.asarray(schedule.columns[response.nc_factor]))

    def check(self, response: KindResponse, checks: Checks, path: Loc) -> None:
        """The response's ``nc_factor`` is the signed factor ``display.rendering_nc`` reads."""
        assert isinstance(response, WithAgainstResponse)
        if not checks.factor_exists(response.nc_factor, path + ("nc_factor",), numeric=True):
            return
        nc = checks.p.display.rendering_nc
        value = None if nc is None else (nc.mm if nc.mm is not None else nc.scale)
        if nc is None or not isinstance(value, FactorRef) or value.factor != response.nc_factor or not nc.signed:
            checks.add(path + ("nc_factor",), f"a with_against response renders each trial with the signed NC of "
                                              f"'{response.nc_factor}': set display.rendering_nc: {{mm: {{factor: "
                                              f"{response.nc_factor}}}, signed: true}}")

    def targets(self, study: StudyInputs) -> list[AnalysisTarget]:
        return [figure_target(study, "pss", "analysis/nc_calibration.py")]


KIND = WithAgainst()
