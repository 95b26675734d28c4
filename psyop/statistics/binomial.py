"""One-tailed binomial tests of pairwise preferences against 50 % (scipy.stats.binomtest)."""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.stats import binomtest

from psyop.statistics.anova import significance_stars


def binomial_test(k: int, n: int, p0: float = 0.5, alternative: str = "greater") -> dict:
    """k successes of n against p0; returns proportion, its SE, Clopper-Pearson 95 % CI, p."""
    res = binomtest(int(k), int(n), p0, alternative=alternative)
    ci = res.proportion_ci(confidence_level=0.95, method="exact")
    prop = k / n if n else float("nan")
    return {
        "k": int(k), "n": int(n), "proportion": prop,
        "se": float(np.sqrt(prop * (1 - prop) / n)) if n else float("nan"),
        "ci_low": float(ci.low), "ci_high": float(ci.high), "p": float(res.pvalue),
        "alternative": alternative, "p0": p0, "stars": significance_stars(float(res.pvalue)),
    }


def pairwise_preferences(
    trials: pd.DataFrame, pairs: list[tuple[str, str]] | None = None,
    subject: str = "participant", alternative: str = "greater",
) -> pd.DataFrame:
    """For each pair (first, second): how often ``first`` was chosen, tested against 50 %.

    Uses ``mode_a``, ``mode_b``, ``chosen_mode`` (trials without a choice are dropped and
    counted in ``n_missing``). ``se_subjects`` is the standard error across subjects'
    proportions (the paper's error bars); ``se`` is the binomial SE over trials.
    """
    answered = trials[trials["chosen_mode"].notna()]
    if pairs is None:
        seen = {tuple(sorted((a, b))) for a, b in zip(trials["mode_a"], trials["mode_b"])}
        pairs = sorted(seen)
    rows = []
    for first, second in pairs:
        mask = ((answered["mode_a"] == first) & (answered["mode_b"] == second)) | (
            (answered["mode_a"] == second) & (answered["mode_b"] == first))
        sub = answered[mask]
        all_mask = ((trials["mode_a"] == first) & (trials["mode_b"] == second)) | (
            (trials["mode_a"] == second) & (trials["mode_b"] == first))
        chose_first = (sub["chosen_mode"] == first)
        per_subject = chose_first.groupby(sub[subject]).mean()
        row: dict[str, object] = {"first": first, "second": second, "pair": f"{first}|{second}"}
        row.update(binomial_test(int(chose_first.sum()), len(sub), 0.5, alternative))
        row["se_subjects"] = float(per_subject.std(ddof=1) / np.sqrt(len(per_subject))) if len(per_subject) > 1 else float("nan")
        row["n_subjects"] = int(per_subject.size)
        row["n_missing"] = int(all_mask.sum() - len(sub))
        rows.append(row)
    return pd.DataFrame(rows)
