"""``with_against``: did the scene move with the eye or against it (NC nulling, one interval; docs/protocols.md,
"NC calibration"). Columns ``mode`` (from the sign of the rendered NC) and ``rendered_nc_mm``."""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar, Literal

import numpy as np
from pydantic import Field, PrivateAttr

from psyop.errors import UserError
from psyop.optics.rig import NcRule
from psyop.protocol.base import Number
from psyop.protocol.kinds.base import (AnalysisTarget, Checks, KindResponse, ObserverBase, ProtocolParts,
                                       ResponseKindSpec, ScheduleInput, StudyInputs, figure_target, normal_cdf)
from psyop.protocol.scene import FactorRef
from psyop.records import Loc, TrialRow


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


#: The sign of the NC each rendering mode renders (psyop.optics.camera: the centre of projection's lateral
#: offset from the centre of rotation is +N ocular, 0 conventional, mirrored reversed).
MODE_NC_SIGN: dict[str, float] = {"ocular": 1.0, "conventional": 0.0, "reversed": -1.0}


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
    declared: ClassVar[bool] = True
    #: the camera's NC rule and the eye model's NC (m), which the plan passes (``rendering_nc``, ``eye_model_nc_m``)
    _rule: NcRule | None = PrivateAttr(default=None)
    _eye_model_nc_m: float = PrivateAttr(default=0.0)

    @classmethod
    def for_session(cls, params: Mapping[str, object]) -> "NcNulling":
        """The model with the rig's NC rule and eye model NC (the plan's ``rendering_nc`` and ``eye_model_nc_m``)."""
        model = cls.model_validate({k: v for k, v in params.items() if k in cls.model_fields})
        rule, eye_nc_m = params.get("rendering_nc"), params.get("eye_model_nc_m")
        for key, value in (("rendering_nc", rule), ("eye_model_nc_m", eye_nc_m)):
            if value is None:
                raise UserError(f"observer: missing parameter {key!r}", "protocol observer")
        assert isinstance(rule, Mapping) and isinstance(eye_nc_m, (int, float))
        model._rule, model._eye_model_nc_m = NcRule(**dict(rule)), float(eye_nc_m)
        return model

    def participant_draws(self, rng: np.random.Generator) -> dict[str, float]:
        """The participant's own NC, ``own_nc_mm`` = nc_mm + N(0, between_subject_sd_mm)."""
        sd = float(self.between_subject_sd_mm)
        shift = float(rng.normal(0.0, sd)) if sd > 0 else 0.0
        return {"own_nc_mm": float(self.nc_mm) + shift}

    def rendered_nc_mm(self, row: TrialRow) -> float:
        """The signed NC this trial is rendered with (mm): the mode's sign times the camera's NC."""
        mode = str(row["mode_interval1"])
        if mode not in MODE_NC_SIGN:
            raise UserError(f"observer: trial {row.get('trial')} has no rendering mode ({mode!r})", "protocol observer")
        if self._rule is None:
            raise UserError("observer: missing parameter 'rendering_nc'", "protocol observer")
        return MODE_NC_SIGN[mode] * self._rule.nc_m_for(self._eye_model_nc_m, row) * 1000.0

    def probability(self, row: TrialRow, participant: Mapping[str, float]) -> float:
        """p(against) in trial ``row``."""
        z = (self.rendered_nc_mm(row) - participant["own_nc_mm"]) / float(self.width_mm)
        return float(self.lapse) + (1.0 - 2.0 * float(self.lapse)) * normal_cdf(z)

    def answer(self, row: TrialRow, participant: Mapping[str, float], u: float) -> str:
        """``against`` when ``u < p``, else ``with``."""
        return "against" if u < self.probability(row, participant) else "with"


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
    takes_confidence = True  # one discrete choice: a confidence rating may follow
    model = WithAgainstResponse
    observer_models = (NcNulling,)
    keys = {"w": "with", "a": "against", "left": "with", "right": "against"}
    buttons = {"1": "with", "2": "against", "L": "with", "R": "against"}
    controller = {"left": "with", "right": "against"}
    fields = {"WithAgainstResponse": {"kind": "plan", "question": "plan", "nc_factor": "kinds"},
              "NcNulling": {k: "kinds" for k in ("kind", "nc_mm", "width_mm", "lapse", "between_subject_sd_mm")}}

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
