"""Repeated-measures ANOVA (one- and two-way within-subject) with pingouin >= 0.7.0.

Reports, for every effect including the interaction: F, uncorrected df and p, Mauchly's
W and p, the Greenhouse-Geisser epsilon, GG-corrected df (df * eps) and GG-corrected p.
pingouin drops a subject with any missing cell (listwise deletion) without saying so;
psyop finds those subjects first, drops them itself, and lists who and why in
:attr:`AnovaResult.dropped`.
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Sequence
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import pandas as pd
import pingouin as pg

ANOVA_COLUMNS = [
    "effect", "F", "df1", "df2", "p_unc", "eps_gg", "df1_gg", "df2_gg", "p_gg",
    "mauchly_W", "mauchly_p", "sphericity", "ng2", "n_subjects",
]


@dataclass(frozen=True)
class AnovaResult:
    """Tidy ANOVA table (one row per effect) and the subjects dropped before fitting."""

    table: pd.DataFrame
    dropped: pd.DataFrame  # columns: subject, reason
    within: tuple[str, ...]
    dv: str
    n_subjects: int

    def effect(self, name: str) -> pd.Series:
        """The row of one effect; interactions are named 'a * b'."""
        rows = self.table[self.table["effect"] == name]
        if rows.empty:
            raise KeyError(f"no effect {name!r}; have {list(self.table['effect'])}")
        return rows.iloc[0]


@contextmanager
def _quiet_pingouin():
    """Silence only the pandas-3 'inplace' deprecation pingouin 0.7.0 triggers in rm_anova."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r"The inplace keyword in DataFrame\.dropna is deprecated")
        yield


def cell_means(trials: pd.DataFrame, dv: str, within: Sequence[str], subject: str = "participant") -> pd.DataFrame:
    """Per-subject cell means of ``dv`` (e.g. proportion correct from a bool ``correct``)."""
    within = list(within)
    answered = trials[trials[dv].notna()].copy()
    answered[dv] = answered[dv].astype(float)
    out = answered.groupby([subject, *within], observed=True)[dv].agg(["mean", "size"]).reset_index()
    return out.rename(columns={"mean": dv, "size": "n_trials"})


def find_incomplete_subjects(data: pd.DataFrame, dv: str, within: Sequence[str], subject: str) -> pd.DataFrame:
    """Subjects lacking a finite ``dv`` in some within-cell, with the missing cells named."""
    within = list(within)
    levels = [sorted(data[w].dropna().unique(), key=str) for w in within]
    complete = data[np.isfinite(pd.to_numeric(data[dv], errors="coerce"))]
    present = {tuple(r) for r in complete[[subject, *within]].itertuples(index=False)}
    rows = []
    for s in sorted(data[subject].unique(), key=str):
        missing = [c for c in itertools.product(*levels) if (s, *c) not in present]
        if missing:
            cells = "; ".join(", ".join(f"{w}={v}" for w, v in zip(within, c)) for c in missing)
            rows.append({"subject": s, "reason": f"missing cell(s): {cells}"})
    return pd.DataFrame(rows, columns=["subject", "reason"])


def rm_anova(data: pd.DataFrame, dv: str, within: str | Sequence[str], subject: str = "participant") -> AnovaResult:
    """One- or two-way repeated-measures ANOVA with sphericity tests and GG correction.

    ``data`` holds one value per subject and cell (use :func:`cell_means` on trials).
    Duplicate cells are an error, not silently averaged.
    """
    within = [within] if isinstance(within, str) else list(within)
    if not 1 <= len(within) <= 2:
        raise ValueError("rm_anova supports one or two within-subject factors")
    if data.duplicated([subject, *within]).any():
        raise ValueError("more than one value per subject and cell; aggregate first (cell_means)")
    dropped = find_incomplete_subjects(data, dv, within, subject)
    kept = data[~data[subject].isin(dropped["subject"])].copy()
    kept[dv] = kept[dv].astype(float)
    n = int(kept[subject].nunique())
    max_levels = max(kept[w].nunique() for w in within)
    if n < max(2, max_levels):
        raise ValueError(f"{n} complete subject(s) cannot test sphericity of {max_levels} levels "
                         f"(dropped: {list(dropped['subject'])})")
    with _quiet_pingouin():
        aov = pg.rm_anova(kept, dv=dv, within=within if len(within) > 1 else within[0],
                          subject=subject, correction=True, detailed=True)
    rows = []
    if len(within) == 1:
        effect, error = aov.iloc[0], aov.iloc[1]
        rows.append(_row(within[0], effect, int(effect["DF"]), int(error["DF"]), n))
    else:
        for _, effect in aov.iterrows():
            rows.append(_row(effect["Source"], effect, int(effect["ddof1"]), int(effect["ddof2"]), n))
    table = pd.DataFrame(rows, columns=ANOVA_COLUMNS)
    return AnovaResult(table=table, dropped=dropped, within=tuple(within), dv=dv, n_subjects=n)


def _row(name: str, effect: pd.Series, df1: int, df2: int, n: int) -> dict:
    eps = float(effect.get("eps", 1.0))
    if df1 == 1 or not np.isfinite(eps):
        eps = 1.0
    p_unc = float(effect["p_unc"])
    p_gg = float(effect.get("p_GG_corr", np.nan))
    if not np.isfinite(p_gg):
        p_gg = p_unc  # pingouin leaves it empty when eps == 1 (two levels)
    return {
        "effect": name, "F": float(effect["F"]), "df1": df1, "df2": df2, "p_unc": p_unc,
        "eps_gg": eps, "df1_gg": df1 * eps, "df2_gg": df2 * eps, "p_gg": p_gg,
        "mauchly_W": float(effect.get("W_spher", np.nan)) if df1 > 1 else 1.0,
        "mauchly_p": float(effect.get("p_spher", np.nan)) if df1 > 1 else 1.0,
        "sphericity": bool(effect.get("sphericity", True)) if df1 > 1 else True,
        "ng2": float(effect["ng2"]), "n_subjects": n,
    }


def posthoc_paired(
    data: pd.DataFrame, dv: str, factor: str, by: str | None = None, subject: str = "participant",
    family: str = "per_level",
) -> pd.DataFrame:
    """Pairwise paired t-tests between levels of ``factor`` (at each level of ``by``), Bonferroni.

    ``family='per_level'`` corrects over the comparisons within each level of ``by`` (the
    paper: "pairwise t-tests between rendering modes at each separation distance");
    ``family='all'`` corrects over every comparison in the table. Subjects with missing
    cells are dropped as in :func:`rm_anova`.
    """
    within = [factor] + ([by] if by else [])
    dropped = find_incomplete_subjects(data, dv, within, subject)
    kept = data[~data[subject].isin(dropped["subject"])]
    groups = [(None, kept)] if by is None else list(kept.groupby(by, sort=True))
    rows = []
    for level, sub in groups:
        levels = sorted(sub[factor].unique(), key=str)
        wide = sub.pivot(index=subject, columns=factor, values=dv).astype(float)
        for a, b in itertools.combinations(levels, 2):
            t = pg.ttest(wide[a], wide[b], paired=True)
            rows.append({
                "by": level, "A": a, "B": b, "mean_A": wide[a].mean(), "mean_B": wide[b].mean(),
                "T": float(t["T"].iloc[0]), "dof": float(t["dof"].iloc[0]), "p_unc": float(t["p_val"].iloc[0]),
                "n_subjects": len(wide),
            })
    out = pd.DataFrame(rows)
    if out.empty:
        return out
    if family == "all":
        out["m"] = len(out)
    elif family == "per_level":
        out["m"] = out.groupby("by", dropna=False)["A"].transform("size")
    else:
        raise ValueError("family must be 'per_level' or 'all'")
    out["p_bonf"] = np.minimum(out["p_unc"] * out["m"], 1.0)
    out["stars"] = out["p_bonf"].map(significance_stars)
    if by is not None:
        out = out.rename(columns={"by": by})
    else:
        out = out.drop(columns="by")
    return out


def significance_stars(p: float) -> str:
    """'***' p <= 0.001, '**' p <= 0.01, '*' p <= 0.05, '' otherwise (the paper's figures)."""
    if not np.isfinite(p):
        return ""
    return "***" if p <= 0.001 else "**" if p <= 0.01 else "*" if p <= 0.05 else ""
