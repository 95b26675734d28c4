"""The procedures' own final estimates, beside the psignifit fits of the same trials.

The last counted trial (not practice, answered) of each participant and condition logs the
procedure's estimate after all of that condition's trials (psyop.adaptive.session), so no
protocol is needed to read it back.

Fitting adaptive data: psyop.statistics.psychometric groups trials by their exact level (every
distinct level is one block of psignifit's ``[level, n_correct, n_total]`` rows). Nothing is
binned: the binomial likelihood of off-grid levels is exact, only the deviance goodness-of-fit
test has little power with many one-trial blocks.
"""

from __future__ import annotations

from typing import Sequence

import pandas as pd

PROCEDURE_COLUMNS = ["procedure", "procedure_trials", "procedure_estimate", "procedure_estimate_sd"]


def final_estimates(trials: pd.DataFrame, group_columns: Sequence[str]) -> pd.DataFrame:
    """One row per group: the procedure, its trial count and final estimate (mean, SD), in the
    level factor's unit (column names end in it, e.g. ``procedure_estimate_D``)."""
    if "adaptive_procedure" not in trials:
        raise ValueError("these trials have no adaptive levels (no adaptive_procedure column)")
    estimate = next(c for c in trials.columns if c.startswith("adaptive_estimate_") and "_sd_" not in c)
    unit = estimate.rsplit("_", 1)[-1]
    counted = trials[trials["correct"].notna()]
    if "practice" in counted:
        counted = counted[~counted["practice"].astype(bool)]
    last = counted.sort_values("trial").groupby(list(group_columns), sort=True).tail(1)
    n = counted.groupby(list(group_columns), sort=True).size().rename("procedure_trials").reset_index()
    out = last[[*group_columns, "adaptive_procedure", estimate, f"adaptive_estimate_sd_{unit}"]].rename(columns={
        "adaptive_procedure": "procedure", estimate: f"procedure_estimate_{unit}",
        f"adaptive_estimate_sd_{unit}": f"procedure_estimate_sd_{unit}"})
    return out.merge(n, on=list(group_columns)).reset_index(drop=True)


def with_procedure_estimates(fits: pd.DataFrame, trials: pd.DataFrame, group_columns: Sequence[str]) -> pd.DataFrame:
    """``fits`` (one row per group, e.g. fit_psychometric_table's) with the procedure's final
    estimate beside each psignifit threshold."""
    return fits.merge(final_estimates(trials, group_columns), on=list(group_columns), how="left")
