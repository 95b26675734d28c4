"""Linear regressions with statsmodels.

- :func:`linear_fit`: y = intercept + slope * x (discrimination threshold vs offset;
  reach vs target per condition).
- :func:`condition_interaction`: y ~ x * C(condition), which tests whether slopes and
  intercepts differ between conditions (the paper's "multiple regression analysis"),
  with a joint F-test of both differences against the pooled line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
import statsmodels.api as sm
import statsmodels.formula.api as smf


@dataclass(frozen=True)
class LinearFit:
    slope: float
    slope_se: float
    slope_ci_low: float
    slope_ci_high: float
    slope_p: float
    intercept: float
    intercept_se: float
    intercept_ci_low: float
    intercept_ci_high: float
    intercept_p: float
    r2: float
    n: int


@dataclass(frozen=True)
class ConditionComparison:
    """y ~ x * C(condition): differences of the non-reference condition from the reference."""

    reference: str
    other: str
    intercept_diff: float
    intercept_diff_p: float
    slope_diff: float
    slope_diff_p: float
    joint_F: float
    joint_df1: int
    joint_df2: int
    joint_p: float
    n: int


def _clean(data: pd.DataFrame, cols: list[str]) -> pd.DataFrame:
    out = data[cols].dropna().copy()
    return out


def linear_fit(data: pd.DataFrame, x: str, y: str) -> LinearFit:
    """OLS fit of ``y`` on ``x``; rows with a missing x or y are dropped."""
    d = _clean(data, [x, y]).rename(columns={x: "x", y: "y"}).astype(float)
    if len(d) < 3:
        raise ValueError(f"need at least 3 complete rows for a line, have {len(d)}")
    m = smf.ols("y ~ x", data=d).fit()
    ci = m.conf_int()
    return LinearFit(
        slope=float(m.params["x"]), slope_se=float(m.bse["x"]), slope_ci_low=float(ci.loc["x", 0]),
        slope_ci_high=float(ci.loc["x", 1]), slope_p=float(m.pvalues["x"]),
        intercept=float(m.params["Intercept"]), intercept_se=float(m.bse["Intercept"]),
        intercept_ci_low=float(ci.loc["Intercept", 0]), intercept_ci_high=float(ci.loc["Intercept", 1]),
        intercept_p=float(m.pvalues["Intercept"]), r2=float(m.rsquared), n=int(m.nobs),
    )


def linear_fits_by(data: pd.DataFrame, x: str, y: str, by: str) -> pd.DataFrame:
    """One :func:`linear_fit` per level of ``by`` as a tidy table."""
    rows = []
    for level, sub in data.groupby(by, sort=True):
        rows.append({by: level, **linear_fit(sub, x, y).__dict__})
    return pd.DataFrame(rows)


def condition_interaction(data: pd.DataFrame, x: str, y: str, condition: str, reference: str | None = None) -> ConditionComparison:
    """Test whether intercept and slope of ``y`` on ``x`` differ between two conditions.

    Fits y = b0 + b1 x + b2 [other] + b3 x [other] (OLS): b2 is the intercept difference,
    b3 the slope difference; the joint F-test compares it with the pooled line y = a + b x.
    """
    d = _clean(data, [x, y, condition]).rename(columns={x: "x", y: "y", condition: "cond"})
    d["x"] = d["x"].astype(float)
    d["y"] = d["y"].astype(float)
    levels = sorted(d["cond"].astype(str).unique())
    if len(levels) != 2:
        raise ValueError(f"condition_interaction needs exactly two conditions, have {levels}")
    reference = reference or levels[0]
    other = [lv for lv in levels if lv != reference][0]
    is_other = (d["cond"].astype(str) == other).to_numpy(float)
    x_, y_ = d["x"].to_numpy(float), d["y"].to_numpy(float)
    ones = np.ones_like(x_)
    full = sm.OLS(y_, np.column_stack([ones, x_, is_other, x_ * is_other])).fit()
    pooled = sm.OLS(y_, np.column_stack([ones, x_])).fit()
    f_value, p_value, df_diff = full.compare_f_test(pooled)
    return ConditionComparison(
        reference=reference, other=other,
        intercept_diff=float(full.params[2]), intercept_diff_p=float(full.pvalues[2]),
        slope_diff=float(full.params[3]), slope_diff_p=float(full.pvalues[3]),
        joint_F=float(f_value), joint_df1=int(round(df_diff)), joint_df2=int(round(full.df_resid)),
        joint_p=float(p_value), n=int(full.nobs),
    )


def as_frame(result) -> pd.DataFrame:
    """A dataclass result as a one-row tidy table."""
    return pd.DataFrame([result.__dict__])


__all__ = ["LinearFit", "ConditionComparison", "linear_fit", "linear_fits_by", "condition_interaction", "as_frame"]
