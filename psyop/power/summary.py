"""Power per test and sample size: the share of replications with p < alpha, Clopper-Pearson CI."""

from __future__ import annotations

import math
from typing import Sequence

import pandas as pd
from scipy.stats import binomtest

from psyop.power.replicate import ReplicationResult

POWER_COLUMNS = ["test", "participants", "power", "ci_low", "ci_high", "n_significant", "n_replications",
                 "n_not_computed", "n_flagged", "alpha"]


def power_table(results: Sequence[ReplicationResult], alpha: float = 0.05, ci_level: float = 0.95) -> pd.DataFrame:
    """One row per (test, participants). A test that could not be computed in a replication counts
    as not significant there and is counted in ``n_not_computed`` (so power is never inflated); one
    computed by a flagged fallback (e.g. a mixed model fitted as clustered OLS) counts as computed and
    in ``n_flagged``."""
    rows: dict[tuple[str, int], dict] = {}
    order: list[str] = []
    for result in results:
        for outcome in result.outcomes:
            if outcome.test not in order:
                order.append(outcome.test)
            row = rows.setdefault((outcome.test, result.participants), {"k": 0, "n": 0, "nan": 0, "flagged": 0})
            row["n"] += 1
            row["flagged"] += bool(outcome.flag)
            if math.isnan(outcome.p):
                row["nan"] += 1
            elif outcome.p < alpha:
                row["k"] += 1
    out = []
    for (test, participants), row in rows.items():
        ci = binomtest(row["k"], row["n"]).proportion_ci(confidence_level=ci_level, method="exact")
        out.append({"test": test, "participants": participants, "power": row["k"] / row["n"],
                    "ci_low": float(ci.low), "ci_high": float(ci.high), "n_significant": row["k"],
                    "n_replications": row["n"], "n_not_computed": row["nan"], "n_flagged": row["flagged"],
                    "alpha": alpha})
    table = pd.DataFrame(out, columns=POWER_COLUMNS)
    table["test"] = pd.Categorical(table["test"], categories=order, ordered=True)
    table = table.sort_values(["test", "participants"]).reset_index(drop=True)
    table["test"] = table["test"].astype(str)
    return table


def format_table(table: pd.DataFrame) -> str:
    lines = [f"{'test':<48} {'N':>4} {'power':>7}  95% CI (Clopper-Pearson)  not computed  flagged"]
    for _, r in table.iterrows():
        lines.append(f"{r['test']:<48} {int(r['participants']):>4} {r['power']:>7.3f}  "
                     f"[{r['ci_low']:.3f}, {r['ci_high']:.3f}]{'':>10}{int(r['n_not_computed']):>6}{int(r['n_flagged']):>9}")
    return "\n".join(lines)
