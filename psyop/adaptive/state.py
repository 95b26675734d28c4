"""The running state every procedure reports (logged per trial, identical for any history replay)."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class ProcedureState:
    """A procedure after ``trials`` observations.

    ``next_level`` is where the next trial goes (even when ``finished``; a caller that keeps
    going gets a sensible level). ``estimate_mean``/``estimate_sd`` are the running threshold
    estimate: for QUEST+ the posterior mean and SD of the threshold; for a staircase the mean of
    the posterior mean and SD of the threshold given its trials (psyop.adaptive.staircase, calibrated
    by benchmarks/bench_adaptive_calibration.py). ``estimate_defined`` is False for an infinite SD.
    ``step``, ``reversals`` and ``reversal_mean`` are the staircase's step size, reversal count and the
    mean of its counted reversal levels (``nan``, 0 and ``nan`` for QUEST+; ``nan`` before a reversal)."""

    procedure: str
    trials: int
    next_level: float
    finished: bool
    stop_reason: str  # "" while running, else "max_trials", "target_sd" or "reversals"
    estimate_mean: float
    estimate_sd: float
    step: float = math.nan
    reversals: int = 0
    reversal_mean: float = math.nan

    @property
    def estimate_defined(self) -> bool:
        return math.isfinite(self.estimate_sd)
