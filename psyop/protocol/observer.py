"""Simulated-observer parameters (``observer:`` section); ``psyop.session`` implements them.

See docs/architecture.md, "Simulated observers". A discriminated union on ``kind``.
"""

from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import Field, model_validator

from psyop.protocol.base import Number, StrictModel
from psyop.protocol.scene import RenderingMode
from psyop.protocol.simulated_eye import SimulatedEye


class _ObserverBase(StrictModel):
    """What every simulated observer has: ``eye``, the simulated eye and tracker (psyop.protocol.simulated_eye)."""

    eye: SimulatedEye | None = None


class Psychometric2afc(_ObserverBase):
    """p(correct) = 0.5 + (0.5 - lapse) * Phi((level - t) / width_D + z75), where t =
    threshold_D + threshold_slope * row[threshold_offset_column] is the 75 % point (without lapse);
    each simulated participant's threshold is shifted by N(0, between_subject_sd_D)."""

    kind: Literal["psychometric_2afc"]
    level_column: str = "level_D"
    threshold_D: Number = Field(gt=0)
    width_D: Number = Field(gt=0)
    lapse: Number = Field(default=0.0, ge=0, lt=0.5)
    threshold_slope: Number = 0.0
    threshold_offset_column: str | None = None
    between_subject_sd_D: Number = Field(default=0.0, ge=0)

    @model_validator(mode="after")
    def _offset(self) -> "Psychometric2afc":
        if self.threshold_slope != 0.0 and self.threshold_offset_column is None:
            raise ValueError("threshold_slope needs threshold_offset_column (the column it multiplies)")
        return self


Probability = Annotated[Number, Field(ge=0, le=1)]


class OrdinalAccuracy(_ObserverBase):
    """p(correct) by rendering mode and separation: ``p_correct: {ocular: {1: 0.667, 2: 0.758}}``."""

    kind: Literal["ordinal_accuracy"]
    p_correct: dict[RenderingMode, dict[Number, Probability]] = Field(min_length=1)
    between_subject_sd: Number = Field(default=0.0, ge=0, le=0.5, description="sd of p across participants")


class PairwisePreference(_ObserverBase):
    """Bradley-Terry: p(a preferred over b) = s_a / (s_a + s_b)."""

    kind: Literal["pairwise_preference"]
    strength: dict[RenderingMode, Annotated[Number, Field(gt=0)]] = Field(min_length=2)


class ReachCondition(StrictModel):
    """reach_m = slope * target_m + intercept_m + N(0, noise_sd_m)."""

    slope: Number
    intercept_m: Number
    noise_sd_m: Number = Field(ge=0)


class Reach(_ObserverBase):
    """Blind-reach model per rendering condition (keys: levels of the rendering factor)."""

    kind: Literal["reach"]
    arm_reach_m: Number = Field(gt=0.2, le=1.5)
    arm_reach_sd_m: Number = Field(default=0.0, ge=0)
    slope_sd: Number = Field(default=0.0, ge=0, le=1, description="sd of a participant's slope deviation (shared by conditions)")
    intercept_sd_m: Number = Field(default=0.0, ge=0, le=0.5, description="sd of a participant's intercept deviation")
    max_reach_fraction: Number = Field(default=1.0, gt=0.3, le=1.5,
                                       description="the hand ends at most this fraction of arm reach from the eyes")
    by_condition: dict[str, ReachCondition] = Field(min_length=1)


class NcNulling(_ObserverBase):
    """An observer whose own NC is ``nc_mm`` (each simulated participant's drawn around it with sd
    ``between_subject_sd_mm``): p(against) = lapse + (1 - 2 lapse) * Phi((r - nc) / width_mm), r the signed NC
    the trial is rendered with (its camera's mode and NC rule); 'with' otherwise. Its point of subjective
    stability (p = 0.5) is its own NC."""

    kind: Literal["nc_nulling"]
    nc_mm: Number = Field(gt=0, lt=30, description="the observer's own NC, mm")
    width_mm: Number = Field(gt=0, le=30, description="sd of the cumulative normal, mm")
    lapse: Number = Field(default=0.0, ge=0, lt=0.5)
    between_subject_sd_mm: Number = Field(default=0.0, ge=0, le=10)


Observer = Annotated[Union[Psychometric2afc, OrdinalAccuracy, PairwisePreference, Reach, NcNulling],
                     Field(discriminator="kind")]
