"""Adaptive runs in the analysis: reversal-based and fit-based threshold estimates side by side.

Reads the per-trial adaptive columns a session logs (psyop.adaptive.session: ``adaptive_procedure``,
``adaptive_reversals``, ``adaptive_estimate_<U>``, ``adaptive_estimate_sd_<U>``). A reversal trial
is one after which the condition's reversal count went up. Per participant x condition:
``reversal_mean`` (the mean level of the reversal trials), ``procedure_estimate`` / ``_sd`` (the
procedure's own final estimate: QUEST+ posterior, staircase posterior given its trials) and, when a
fit table is given, the psychometric fit's threshold, CI and status.
"""

from __future__ import annotations

from collections.abc import Sequence

import pandas as pd


def adaptive_columns(trials: pd.DataFrame, unit: str) -> tuple[str, str]:
    """The estimate and SD column names for ``unit``; KeyError naming them when absent."""
    est, sd = f"adaptive_estimate_{unit}", f"adaptive_estimate_sd_{unit}"
    missing = [c for c in ("adaptive_procedure", "adaptive_reversals", est, sd) if c not in trials]
    if missing:
        raise KeyError(f"trials lack the adaptive columns {missing}: not an adaptive run")
    return est, sd


def mark_reversals(trials: pd.DataFrame, groups: Sequence[str]) -> pd.DataFrame:
    """Trials in order per group with ``trial_in_track`` (1-based) and ``is_reversal``."""
    order = [c for c in ("trial_index", "trial") if c in trials][:1]
    t = trials.sort_values([*groups, *order], kind="stable").copy()
    rev = t.groupby(list(groups), sort=False)["adaptive_reversals"]
    t["is_reversal"] = rev.diff().fillna(t["adaptive_reversals"]).to_numpy() > 0
    t["trial_in_track"] = t.groupby(list(groups), sort=False).cumcount() + 1
    return t


def estimates_table(trials: pd.DataFrame, level: str, unit: str, groups: Sequence[str],
                    fits: pd.DataFrame | None = None) -> pd.DataFrame:
    """One row per track: trials, reversals, reversal mean, the procedure's estimate and the fit's."""
    est, sd = adaptive_columns(trials, unit)
    t = mark_reversals(trials, groups)
    rows = []
    for key, g in t.groupby(list(groups), sort=True):
        key = key if isinstance(key, tuple) else (key,)
        revs = g.loc[g["is_reversal"], level].astype(float)
        last = g.iloc[-1]
        rows.append({**dict(zip(groups, key)), "procedure": str(last["adaptive_procedure"]), "n_trials": len(g),
                     "n_reversals": int(g["is_reversal"].sum()),
                     "reversal_mean": float(revs.mean()) if len(revs) else float("nan"),
                     "procedure_estimate": float(last[est]), "procedure_estimate_sd": float(last[sd])})
    table = pd.DataFrame(rows)
    if fits is not None and len(table):
        cols = [c for c in ("threshold_D", "threshold_ci_low_D", "threshold_ci_high_D", "threshold_bound_D", "status")
                if c in fits]
        table = table.merge(fits[list(groups) + cols].rename(columns=lambda c: c if c in groups else f"fit_{c}"),
                            on=list(groups), how="left")
    return table


__all__ = ["adaptive_columns", "estimates_table", "mark_reversals"]
