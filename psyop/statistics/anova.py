"""Repeated-measures ANOVA (one- and two-way within-subject) with pingouin >= 0.7.0.

Reports, for every effect including the interaction: F, uncorrected df and p, Mauchly's
W and p, the Greenhouse-Geisser epsilon, GG-corrected df (df * eps) and GG-corrected p.
pingouin drops a subject with any missing cell (listwise deletion) without saying so;
psyop finds those subjects first, drops them itself, and lists who and why in
:attr:`AnovaResult.dropped`.

Degenerate data never produce a number that looks like a result:

- every effect's error sum of squares (the subject x effect interaction) is computed here;
  when it is zero relative to the total (<= :data:`ZERO_SS_REL`, e.g. a level effect plus an
  exact subject offset, where pingouin reports F = 2.7e17 or a *negative* F), the row's
  ``status`` is ``zero_error_variance`` and F, p and eps are NaN;
- a GG epsilon pingouin cannot compute is NaN with ``status`` ``eps_undefined``, never 1
  (eps = 1 only for one-df effects, where it is 1 by definition);
- constant data, a level name only some subjects have (a typo: the subject and level are
  named), and too few complete subjects raise :class:`AnovaInputError` (a
  :class:`psyop.errors.UserError` and a ``ValueError``) with the fix;
- post-hoc pairs whose differences have zero variance get ``status`` ``zero_variance`` and
  NaN t and p instead of numpy warnings or p = 1e-112.
"""

from __future__ import annotations

import itertools
import math
import warnings
from collections.abc import Sequence
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import pandas as pd
import pingouin as pg
from scipy.stats import f as f_dist

from psyop.errors import UserError

ANOVA_COLUMNS = [
    "effect", "F", "df1", "df2", "p_unc", "eps_gg", "df1_gg", "df2_gg", "p_gg",
    "mauchly_W", "mauchly_p", "sphericity", "ng2", "n_subjects", "status",
]
#: An error sum of squares at or below this fraction of the total counts as zero.
ZERO_SS_REL = 1e-10


class AnovaInputError(UserError, ValueError):
    """Data a repeated-measures test cannot be run on; the message names what and whom."""

    def __init__(self, message: str, location: str | None = None):
        UserError.__init__(self, message, location)


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
    if _is_complete_grid(data, dv, within, subject):
        return pd.DataFrame([], columns=["subject", "reason"])  # every subject has every cell
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


def check_level_names(data: pd.DataFrame, within: Sequence[str], subject: str) -> None:
    """Raise :class:`AnovaInputError` when a subject has a level of a factor that most subjects lack
    (a typo or relabelled condition), naming the subject, the level and the expected levels."""
    n_subjects = data[subject].nunique()
    for w in within:
        per_level = data.groupby(w, observed=True)[subject].nunique()
        common = {lv for lv, n in per_level.items() if n > n_subjects / 2}
        odd = [lv for lv, n in per_level.items() if lv not in common]
        if not odd or not common:
            continue
        problems = []
        for lv in odd:
            whose = sorted(data.loc[data[w] == lv, subject].unique(), key=str)
            for s_ in whose:
                have = set(data.loc[data[subject] == s_, w])
                lacks = sorted((str(c) for c in common - have))
                problems.append(f"subject {s_!s} has {w}={lv!s}" + (f" but lacks {w}={', '.join(lacks)}" if lacks else ""))
        raise AnovaInputError(
            f"level names differ between subjects: {'; '.join(problems)} (levels most subjects have: "
            f"{', '.join(sorted(map(str, common)))}); correct the label or drop the subject before the ANOVA")


def _check_enough_subjects(kept: pd.DataFrame, subject: str, need: int, what: str, dropped: pd.DataFrame) -> int:
    n = int(kept[subject].nunique())
    if n < need:
        names = ", ".join(map(str, sorted(kept[subject].unique(), key=str))) or "none"
        gone = f"; dropped for missing cells: {', '.join(map(str, dropped['subject']))}" if len(dropped) else ""
        raise AnovaInputError(f"{n} complete subject(s) ({names}){gone}: {what} needs at least {need}")
    return n


def _is_complete_grid(data: pd.DataFrame, dv: str, within: Sequence[str], subject: str) -> bool:
    """Whether ``data`` holds exactly one row with a finite ``dv`` for every subject and combination of
    levels, with no missing subject or level and no categorical key (the usual complete design); a frame
    with repeated column names is never taken for one."""
    if not data.columns.is_unique:
        return False
    keys = data[[subject, *within]]
    if any(isinstance(keys[c].dtype, pd.CategoricalDtype) for c in keys) or keys.isna().to_numpy().any():
        return False
    if not np.isfinite(pd.to_numeric(data[dv], errors="coerce")).all():
        return False
    n_cells = math.prod(int(keys[c].nunique()) for c in keys)
    return len(data) == n_cells and not keys.duplicated().any()


def _complete_grid_values(data: pd.DataFrame, dv: str, within: Sequence[str], subject: str
                          ) -> tuple[np.ndarray, int] | None:
    """``data.pivot_table(index=subject, columns=within, values=dv, aggfunc="first").to_numpy(float)``
    and its number of first-factor levels for a complete design (:func:`_is_complete_grid`; None
    otherwise): each value placed at its keys' sorted codes (``pd.factorize(sort=True)``, the
    groupby's order), in the pivot's memory layout (row-major subject x cells, as its unstack builds it)."""
    if not _is_complete_grid(data, dv, within, subject):
        return None
    codes = [pd.factorize(data[c], sort=True) for c in (subject, *within)]
    shape = tuple(len(uniques) for _, uniques in codes)
    y = np.empty(shape, float)
    y[tuple(c for c, _ in codes)] = data[dv].to_numpy(float)
    return y.reshape(shape[0], -1), shape[1]


def error_sums_of_squares(data: pd.DataFrame, dv: str, within: Sequence[str], subject: str) -> dict[str, float]:
    """Error sum of squares of each effect (the subject x effect interaction) of a complete design,
    keyed like pingouin's effects ('A', 'B', 'A * B'), plus 'total' (around the grand mean)."""
    within = list(within)
    grid = _complete_grid_values(data, dv, within, subject)
    if grid is None:
        wide = data.pivot_table(index=subject, columns=within, values=dv, aggfunc="first", observed=True)
        y = wide.to_numpy(float)
        a = len(wide.columns.levels[0]) if hasattr(wide.columns, "levels") else 1
    else:
        y, a = grid
    total = float(((y - y.mean()) ** 2).sum())
    if len(within) == 1:
        r = y - y.mean(axis=1, keepdims=True) - y.mean(axis=0, keepdims=True) + y.mean()
        return {within[0]: float((r ** 2).sum()), "total": total}
    y = y.reshape(len(y), a, -1)  # subject x A x B (pivot_table sorts the column MultiIndex)
    b = y.shape[2]
    m_sa, m_sb, m_s = y.mean(axis=2), y.mean(axis=1), y.mean(axis=(1, 2))
    m_a, m_b, g = y.mean(axis=(0, 2)), y.mean(axis=(0, 1)), y.mean()
    r_a = m_sa - m_s[:, None] - m_a[None, :] + g
    r_b = m_sb - m_s[:, None] - m_b[None, :] + g
    m_ab = y.mean(axis=0)
    r_ab = (y - m_sa[:, :, None] - m_sb[:, None, :] + m_s[:, None, None]
            - (m_ab - m_a[:, None] - m_b[None, :] + g)[None])
    return {within[0]: float(b * (r_a ** 2).sum()), within[1]: float(a * (r_b ** 2).sum()),
            f"{within[0]} * {within[1]}": float((r_ab ** 2).sum()), "total": total}


def _only_columns(data: pd.DataFrame, columns: list[str]) -> pd.DataFrame:
    """``data[columns]`` when those are distinct columns of ``data`` (else ``data``): the test reads
    nothing else, and pingouin's pivots and copies of a wide table (e.g. a fit table) cost more."""
    if len(set(columns)) == len(columns) and data.columns.is_unique and all(c in data.columns for c in columns):
        return data[columns]
    return data


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
    check_level_names(data, within, subject)
    dropped = find_incomplete_subjects(data, dv, within, subject)
    kept = _only_columns(data, [subject, *within, dv])
    kept = kept[~kept[subject].isin(dropped["subject"])].copy()
    kept[dv] = kept[dv].astype(float)
    max_levels = max(kept[w].nunique() for w in within) if len(kept) else 0
    n = _check_enough_subjects(kept, subject, max(2, max_levels), f"an rm-ANOVA with {max_levels} levels", dropped)
    error_ss = error_sums_of_squares(kept, dv, within, subject)
    if error_ss["total"] <= 0.0 or np.ptp(kept[dv].to_numpy(float)) == 0.0:
        raise AnovaInputError(f"{dv!r} is the same value ({kept[dv].iloc[0]:g}) in every subject and cell: "
                              "there is no variance to test")
    with _quiet_pingouin(), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # degenerate rows are caught below, by error SS
        aov = pg.rm_anova(kept, dv=dv, within=within if len(within) > 1 else within[0],
                          subject=subject, correction=True, detailed=True)
    rows = []
    zero = {k: v <= ZERO_SS_REL * error_ss["total"] for k, v in error_ss.items() if k != "total"}
    if len(within) == 1:
        effect, error = aov.iloc[0], aov.iloc[1]
        rows.append(_row(within[0], effect, int(effect["DF"]), int(error["DF"]), n, zero[within[0]]))
    else:
        for _, effect in aov.iterrows():
            rows.append(_row(effect["Source"], effect, int(effect["ddof1"]), int(effect["ddof2"]), n,
                             zero[effect["Source"]]))
    table = pd.DataFrame(rows, columns=ANOVA_COLUMNS)
    return AnovaResult(table=table, dropped=dropped, within=tuple(within), dv=dv, n_subjects=n)


def _row(name: str, effect: pd.Series, df1: int, df2: int, n: int, zero_error: bool) -> dict:
    nan = float("nan")
    status = "ok"
    eps = float(effect.get("eps", nan))
    if df1 == 1:
        eps = 1.0  # one numerator df: sphericity holds by definition
    elif not np.isfinite(eps):
        status = "eps_undefined"
    f_value, p_unc = float(effect.get("F", nan)), float(effect.get("p_unc", nan))
    p_gg = float(effect.get("p_GG_corr", nan)) if df1 > 1 else p_unc  # pingouin leaves it empty for one df
    if df1 > 1 and np.isfinite(eps) and not np.isfinite(p_gg) and np.isfinite(f_value) and f_value >= 0:
        p_gg = float(f_dist.sf(f_value, df1 * eps, df2 * eps))  # when pingouin gives none: never a blank p
    if zero_error or not np.isfinite(f_value) or f_value < 0:
        status, f_value, p_unc, p_gg, eps = "zero_error_variance", nan, nan, nan, nan
    return {
        "effect": name, "F": f_value, "df1": df1, "df2": df2, "p_unc": p_unc,
        "eps_gg": eps, "df1_gg": df1 * eps, "df2_gg": df2 * eps, "p_gg": p_gg,
        "mauchly_W": float(effect.get("W_spher", nan)) if df1 > 1 else 1.0,
        "mauchly_p": float(effect.get("p_spher", nan)) if df1 > 1 else 1.0,
        "sphericity": bool(effect.get("sphericity", True)) if df1 > 1 else True,
        "ng2": float(effect.get("ng2", nan)), "n_subjects": n, "status": status,
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
    check_level_names(data, within, subject)
    dropped = find_incomplete_subjects(data, dv, within, subject)
    kept = data[~data[subject].isin(dropped["subject"])]
    _check_enough_subjects(kept, subject, 2, "a paired t-test", dropped)
    groups = [(None, kept)] if by is None else list(kept.groupby(by, sort=True))
    rows = []
    for level, sub in groups:
        levels = sorted(sub[factor].unique(), key=str)
        wide = sub.pivot(index=subject, columns=factor, values=dv).astype(float)
        for a, b in itertools.combinations(levels, 2):
            diff = (wide[a] - wide[b]).to_numpy(float)
            scale = max(np.abs(wide[[a, b]].to_numpy(float)).max(), 1e-300)
            if np.std(diff) <= 1e-9 * scale:  # constant differences: t is infinite or undefined
                t_val, dof, p_val, status = float("nan"), float(len(diff) - 1), float("nan"), "zero_variance"
            else:
                t = pg.ttest(wide[a], wide[b], paired=True)
                t_val, dof, p_val, status = (float(t["T"].iloc[0]), float(t["dof"].iloc[0]),
                                             float(t["p_val"].iloc[0]), "ok")
            rows.append({
                "by": level, "A": a, "B": b, "mean_A": wide[a].mean(), "mean_B": wide[b].mean(),
                "T": t_val, "dof": dof, "p_unc": p_val, "n_subjects": len(wide), "status": status,
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
