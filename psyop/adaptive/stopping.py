"""Stopping rules: a fixed trial count, a target SD of the threshold estimate, or both."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class StopRule:
    """Stop at ``max_trials`` or once the estimate's SD is at most ``target_sd`` (after at least
    ``min_trials``), whichever comes first. At least one of the two must be given."""

    max_trials: int | None = None
    target_sd: float | None = None
    min_trials: int = 0

    def __post_init__(self) -> None:
        if self.max_trials is None and self.target_sd is None:
            raise ValueError("a stop rule needs max_trials, target_sd or both")
        if self.max_trials is not None and self.max_trials < 1:
            raise ValueError(f"max_trials must be >= 1, got {self.max_trials}")
        if self.target_sd is not None and not self.target_sd > 0:
            raise ValueError(f"target_sd must be > 0, got {self.target_sd}")
        if self.min_trials < 0:
            raise ValueError(f"min_trials must be >= 0, got {self.min_trials}")

    def reason(self, trials: int, estimate_sd: float) -> str:
        """"" while the procedure should go on, else why it stops."""
        if self.max_trials is not None and trials >= self.max_trials:
            return "max_trials"
        if (self.target_sd is not None and trials >= self.min_trials and math.isfinite(estimate_sd)
                and estimate_sd <= self.target_sd):
            return "target_sd"
        return ""
