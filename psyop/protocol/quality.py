"""The optional ``quality:`` section: gaze-based exclusion rules, applied at analysis time only.

Nothing recorded is changed: :func:`psyop.quality.rules.apply_rules` reads the per-trial measures
(:data:`psyop.quality.measures.TRIAL_MEASURES`) and lists what each rule excludes. A trial rule bounds
one measure of a trial; a participant rule bounds the participant's median of a measure over their
trials; ``min_included_trials`` excludes a participant left with fewer included trials. A protocol
without the section excludes nothing. docs/protocols.md "Quality rules", docs/quality.md.
"""

from __future__ import annotations

import math

from pydantic import Field, field_validator, model_validator

from psyop.protocol.base import Number, StrictModel
from psyop.protocol.validation import VALIDATION_MEASURES

#: the measures a rule may name (equal to psyop.quality.measures.TRIAL_MEASURES' keys: tests/quality)
QUALITY_MEASURES: tuple[str, ...] = (
    "data_loss_share", "longest_gap_s", "accuracy_fixation_mean_deg", "accuracy_fixation_max_deg",
    "accuracy_fixation_corrected_mean_deg", "accuracy_fixation_left_mean_deg", "accuracy_fixation_right_mean_deg",
    "accuracy_pursuit_mean_deg", "accuracy_pursuit_max_deg",
    "accuracy_pursuit_corrected_mean_deg", "precision_rms_s2s_deg", "precision_sd_deg", "pursuit_gain",
    "pursuit_lag_s", "catch_up_saccades_per_s", "n_fixations", "n_saccades", *VALIDATION_MEASURES)


class QualityRule(StrictModel):
    """One bound on one measure: ``max`` (largest allowed) or ``min`` (smallest allowed), with the
    reason a methods section gives for it (e.g. the paper's words)."""

    measure: str = Field(description="a per-trial measure psyop computes (QUALITY_MEASURES)")
    max: Number | None = None
    min: Number | None = None
    reason: str | None = Field(default=None, description="why, in a methods section's words")

    @field_validator("measure")
    @classmethod
    def _known(cls, value: str) -> str:
        if value not in QUALITY_MEASURES:
            raise ValueError(f"psyop does not compute the measure {value!r}; use one of: {', '.join(QUALITY_MEASURES)}")
        return value

    @model_validator(mode="after")
    def _one_bound(self) -> QualityRule:
        if (self.max is None) == (self.min is None):
            raise ValueError(f"rule on {self.measure}: give exactly one of max: or min:")
        return self

    def fails(self, value: float) -> bool:
        """Whether ``value`` breaks this rule (NaN, i.e. not measured, never does)."""
        if math.isnan(value):
            return False
        if self.max is not None:
            return bool(value > self.max)
        assert self.min is not None  # the validator above requires exactly one of max:/min:
        return bool(value < self.min)

    def describe(self) -> str:
        """e.g. ``data_loss_share > 0.5`` (what excludes)."""
        return f"{self.measure} > {self.max:g}" if self.max is not None else f"{self.measure} < {self.min:g}"


class QualitySection(StrictModel):
    """``quality:``: trial rules, participant rules (on the participant's median over trials) and the
    fewest included trials a participant must keep."""

    trials: list[QualityRule] = Field(default_factory=list, description="a trial breaking one is excluded")
    participants: list[QualityRule] = Field(
        default_factory=list, description="on the participant's median over all their trials; breaking one excludes them")
    min_included_trials: int | None = Field(default=None, ge=1,
                                            description="a participant with fewer included trials is excluded")
    min_included_trials_reason: str | None = None
