"""Linear regressions with statsmodels.

- :func:`linear_fit`: y = intercept + slope * x (discrimination threshold vs offset;
  reach vs target per condition).
- :func:`condition_interaction`: y ~ x * C(condition), which tests whether slopes and
  intercepts differ between conditions (the paper's "multiple regression analysis"),
  with a joint F-test of both differences against the pooled line. It treats every trial as
  independent (pooled); reported beside the primary test.
- :func:`mixed_condition_comparison`: the same contrasts in a linear mixed model with a random
  intercept and slope per participant (statsmodels MixedLM, REML), the subject-aware primary
  test; when that model cannot be fitted it falls back, in order, to a random intercept only and
  to OLS with CR2 participant-clustered standard errors and small-sample df (Satterthwaite t, HTZ F:
  psyop.statistics.small_sample), and says why (``fallback_reason``) and what it flags (``flags``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import warnings

import numpy as np
import pandas as pd
import statsmodels.api as sm
from scipy.stats import chi2
import statsmodels.formula.api as smf

if TYPE_CHECKING:
    from psyop.statistics.small_sample import ClusterRobustTest


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
    # the design matrix patsy builds for ``smf.ols("y ~ x")`` (C-ordered [1, x] columns), fitted directly:
    # the same numbers without the formula machinery (tests/statistics/test_regression_direct_ols.py)
    x_ = d["x"].to_numpy(float)
    m = sm.OLS(d["y"].to_numpy(float), np.column_stack([np.ones_like(x_), x_])).fit()
    ci = m.conf_int()
    return LinearFit(
        slope=float(m.params[1]), slope_se=float(m.bse[1]), slope_ci_low=float(ci[1, 0]),
        slope_ci_high=float(ci[1, 1]), slope_p=float(m.pvalues[1]),
        intercept=float(m.params[0]), intercept_se=float(m.bse[0]),
        intercept_ci_low=float(ci[0, 0]), intercept_ci_high=float(ci[0, 1]),
        intercept_p=float(m.pvalues[0]), r2=float(m.rsquared), n=int(m.nobs),
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


@dataclass(frozen=True)
class MixedComparison:
    """Condition differences with participants as a random factor (or the stated fallback)."""

    method: str
    fallback_reason: str  # '' when the random intercept + slope model was fitted
    reference: str
    other: str
    slope: float  # reference condition's fixed-effect slope
    intercept: float
    intercept_diff: float
    intercept_diff_p: float
    slope_diff: float
    slope_diff_p: float
    joint_chi2: float  # the Wald statistic Q of both differences (chi2 under the mixed model's asymptotics)
    joint_df: int
    joint_p: float
    n: int
    n_subjects: int
    #: how the joint test was referred: 'Wald chi2' (MixedLM, asymptotic), 'HTZ F' (CR2 small-sample),
    #: 'F' (OLS, one participant)
    joint_test: str = "Wald chi2"
    joint_statistic: float = float("nan")  # chi2, or the (HTZ-scaled) F
    joint_df_denom: float = float("inf")  # inf for chi2
    #: ';'-joined flags: 'low_df' (denominator df < MIN_RELIABLE_DF), 'few_participants' (a mixed model
    #: or cluster-robust test from fewer than MIN_PARTICIPANTS participants), 'one_participant'
    flags: str = ""
    flag_text: str = ""  # the flags in words (what a reader must know about this p-value)


#: A random-effects variance or a cluster-robust covariance from fewer participants than this is
#: flagged: with so few groups variance components are poorly estimated and the mixed model's Wald
#: chi2 and z tests (which ignore their uncertainty) are anti-conservative (Bolker et al. 2009, TREE
#: 24:127, recommend at least 5-6 levels of a random factor).
MIN_PARTICIPANTS = 5


def _mixed_fit(d: pd.DataFrame, re_formula: str):
    from statsmodels.tools.sm_exceptions import ConvergenceWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fit = smf.mixedlm("y ~ xc * other", d, groups=d["subject"], re_formula=re_formula.replace("x", "xc")).fit(reml=True)
    # statsmodels warns "MLE may be on the boundary" whenever its Hessian check is inconclusive;
    # psyop judges the fitted covariance itself: a variance below 0.1 % of the residual variance
    # (or a non-finite one) means the model is not identified on these data.
    problems = [str(w.message).splitlines()[0] for w in caught
                if issubclass(w.category, ConvergenceWarning) and "boundary" not in str(w.message)]
    if not getattr(fit, "converged", True):
        problems.append("optimizer did not converge")
    cov = np.atleast_2d(np.asarray(fit.cov_re, float))
    if not np.all(np.isfinite(cov)) or np.linalg.eigvalsh(cov).min() <= 1e-3 * float(fit.scale):
        problems.append("random-effects covariance is singular (a variance estimated at ~0)")
    if not np.all(np.isfinite(fit.bse[["other", "xc:other"]])):
        problems.append("standard errors are not finite")
    return fit, problems


def _first_mixed_fit(d: pd.DataFrame, n_subjects: int):
    """The first mixed model that fits (random intercept and slope, then intercept only):
    ``(fit or None, method, reasons)``, where ``reasons`` says why each one before it failed."""
    reasons: list[str] = []
    if n_subjects < 3:
        reasons.append(f"only {n_subjects} participant(s): no between-participant variance to estimate")
        return None, "", reasons
    for re_formula, name in (("~x", "MixedLM, random intercept and slope per participant (REML)"),
                             ("~1", "MixedLM, random intercept per participant (REML)")):
        try:
            candidate, problems = _mixed_fit(d, re_formula)
        except (np.linalg.LinAlgError, ValueError) as exc:
            candidate, problems = None, [f"{type(exc).__name__}: {exc}"]
        if not problems:
            return candidate, name, reasons
        reasons.append(f"{name.split(', ')[1].split(' (')[0]}: {'; '.join(problems)}")
    return None, "", reasons


def mixed_condition_comparison(data: pd.DataFrame, x: str, y: str, condition: str, subject: str = "participant",
                               reference: str | None = None) -> MixedComparison:
    """Do intercept and slope of ``y`` on ``x`` differ between two conditions, participants random?

    Model: y = b0 + b1 x + b2 [other] + b3 x [other] + u0_s + u1_s x + e, (u0, u1) ~ N(0, G) per
    participant (MixedLM, REML). b2, b3 are tested by Wald z; both jointly by a Wald chi2 (2 df).
    Fallbacks (``method`` and ``fallback_reason`` say which and why): random intercept only when
    the slope variance is not estimable; OLS with CR2 participant-clustered SEs and small-sample df
    (Satterthwaite, HTZ) when no mixed model fits. Few participants and low df are flagged (``flags``).
    """
    d = _clean(data, [x, y, condition, subject]).rename(columns={x: "x", y: "y", condition: "cond", subject: "subject"})
    d["x"], d["y"] = d["x"].astype(float), d["y"].astype(float)
    levels = sorted(d["cond"].astype(str).unique())
    if len(levels) != 2:
        raise ValueError(f"mixed_condition_comparison needs exactly two conditions, have {levels}")
    reference = reference or levels[0]
    other = [lv for lv in levels if lv != reference][0]
    d["other"] = (d["cond"].astype(str) == other).astype(float)
    x_mean = float(d["x"].mean())
    d["xc"] = d["x"] - x_mean
    n_subjects = int(d["subject"].nunique())
    fit, method, reasons = _first_mixed_fit(d, n_subjects)
    if fit is None:
        return _cr2_fallback(d, x_mean, method_reasons=reasons, reference=reference, other=other, n_subjects=n_subjects)
    # x is centred for the fit (intercept and slope variances are otherwise nearly collinear and
    # the covariance lands on its boundary); intercepts are reported at x = 0 by linear contrasts.
    names = list(fit.fe_params.index)

    def contrast(weights: dict[str, float]):
        vec = np.zeros(len(names))
        for k, v in weights.items():
            vec[names.index(k)] = v
        res = fit.t_test(vec.reshape(1, -1), use_t=False)
        return float(np.squeeze(res.effect)), float(np.squeeze(res.pvalue))
    intercept, _ = contrast({"Intercept": 1.0, "xc": -x_mean})
    intercept_diff, intercept_diff_p = contrast({"other": 1.0, "xc:other": -x_mean})
    terms = ["other", "xc:other"]
    b = np.asarray(fit.params[terms], float)
    v = np.asarray(fit.cov_params().loc[terms, terms], float)
    joint_chi2 = float(b @ np.linalg.solve(v, b))
    flags, texts = [], []
    if n_subjects < MIN_PARTICIPANTS:
        flags.append("few_participants")
        texts.append(f"FEW PARTICIPANTS: random effects estimated from {n_subjects} < {MIN_PARTICIPANTS} participants; "
                     "the asymptotic Wald chi2 ignores their uncertainty and is optimistic")
    return MixedComparison(
        method=method, fallback_reason="; ".join(reasons), reference=reference, other=other,
        slope=float(fit.params["xc"]), intercept=intercept,
        intercept_diff=intercept_diff, intercept_diff_p=intercept_diff_p,
        slope_diff=float(fit.params["xc:other"]), slope_diff_p=float(fit.pvalues["xc:other"]),
        joint_chi2=joint_chi2, joint_df=2, joint_p=float(chi2.sf(joint_chi2, 2)), n=int(len(d)), n_subjects=n_subjects,
        joint_test="Wald chi2", joint_statistic=joint_chi2, joint_df_denom=float("inf"),
        flags=";".join(flags), flag_text="; ".join(texts),
    )


def _joint_cr2(design: np.ndarray, y: np.ndarray, clusters: np.ndarray,
               contrasts: np.ndarray) -> tuple[ClusterRobustTest | None, str]:
    """The HTZ F of both differences, or None and why cr2_test refused it (its ValueError's text)."""
    from psyop.statistics.small_sample import cr2_test

    try:
        return cr2_test(design, y, clusters, contrasts), ""
    except ValueError as exc:
        return None, str(exc)


def _cr2_fallback(d: pd.DataFrame, x_mean: float, method_reasons: list[str], reference: str, other: str,
                  n_subjects: int) -> MixedComparison:
    """No mixed model fits: OLS of y ~ xc * other with CR2 participant-clustered errors, Satterthwaite t for
    each difference and the HTZ F for both (psyop.statistics.small_sample; clubSandwich's defaults). With
    one participant there is nothing to cluster: plain OLS, flagged."""
    from psyop.statistics.small_sample import MIN_RELIABLE_DF, cr2_test

    xc, other_col, y = d["xc"].to_numpy(float), d["other"].to_numpy(float), d["y"].to_numpy(float)
    design = np.column_stack([np.ones_like(xc), xc, other_col, xc * other_col])
    intercept_w = np.array([1.0, -x_mean, 0.0, 0.0])
    intercept_diff_w = np.array([0.0, 0.0, 1.0, -x_mean])
    slope_diff_w = np.array([0.0, 0.0, 0.0, 1.0])
    joint_c = np.array([[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
    flags, texts = [], []
    if n_subjects >= 2:
        clusters = d["subject"].astype(str).to_numpy()
        method = ("OLS with CR2 participant-clustered standard errors (Satterthwaite t, HTZ F; "
                  "small-sample cluster-robust, as R's clubSandwich)")
        inter = cr2_test(design, y, clusters, intercept_w)
        idiff = cr2_test(design, y, clusters, intercept_diff_w)
        sdiff = cr2_test(design, y, clusters, slope_diff_w)
        beta = np.linalg.lstsq(design, y, rcond=None)[0]
        values = dict(intercept=inter.estimate[0], intercept_diff=idiff.estimate[0], intercept_diff_p=idiff.p,
                      slope_diff=sdiff.estimate[0], slope_diff_p=sdiff.p, slope=float(beta[1]))
        joint, refused = _joint_cr2(design, y, clusters, joint_c)
        if joint is None:  # 2 clusters cannot inform 2 contrasts: refused, not a number
            flags.append("joint_not_testable")
            texts.append(f"JOINT TEST NOT COMPUTED with {n_subjects} participants: {refused}")
            values.update(joint_chi2=float("nan"), joint_p=float("nan"),
                          joint_statistic=float("nan"), joint_df_denom=float("nan"))
        else:
            values.update(joint_chi2=joint.wald_q, joint_p=joint.p, joint_statistic=joint.statistic,
                          joint_df_denom=joint.df_denom)
        joint_test = "HTZ F"
        if n_subjects < MIN_PARTICIPANTS:
            flags.append("few_participants")
            texts.append(f"FEW PARTICIPANTS: {n_subjects} clusters (< {MIN_PARTICIPANTS}); CR2 with small-sample df is "
                         "the established correction, but its power is low and its df small")
        low = [f"{name} {t.df_denom:.3g}" for name, t in (("joint", joint), ("slope difference", sdiff),
                                                            ("intercept difference", idiff)) if t is not None and t.low_df]
        if low:
            flags.append("low_df")
            texts.append(f"LOW DF: small-sample df {', '.join(low)} < {MIN_RELIABLE_DF:g}; the approximation is "
                         "unreliable there (Tipton 2015): treat these p-values as descriptive")
    else:
        fit = sm.OLS(y, design).fit()
        method = "OLS (one participant: reaches as independent, no generalisation to participants)"
        joint_f = fit.f_test(joint_c)
        values = dict(intercept=float(intercept_w @ fit.params), intercept_diff=float(intercept_diff_w @ fit.params),
                      intercept_diff_p=float(np.squeeze(fit.t_test(intercept_diff_w.reshape(1, -1)).pvalue)),
                      slope_diff=float(fit.params[3]), slope_diff_p=float(fit.pvalues[3]),
                      joint_chi2=float(np.squeeze(joint_f.fvalue)) * 2, joint_p=float(np.squeeze(joint_f.pvalue)),
                      joint_statistic=float(np.squeeze(joint_f.fvalue)),
                      joint_df_denom=float(fit.df_resid), slope=float(fit.params[1]))
        joint_test = "F"
        flags.append("one_participant")
        texts.append("ONE PARTICIPANT: the test is about this participant's reaches only")
    return MixedComparison(method=method, fallback_reason="; ".join(method_reasons), reference=reference, other=other,
                           joint_df=2, n=int(len(d)), n_subjects=n_subjects, joint_test=joint_test, flags=";".join(flags),
                           flag_text="; ".join(texts), **values)


def as_frame(result) -> pd.DataFrame:
    """A dataclass result as a one-row tidy table."""
    return pd.DataFrame([result.__dict__])


__all__ = ["LinearFit", "ConditionComparison", "MixedComparison", "linear_fit", "linear_fits_by", "condition_interaction",
           "mixed_condition_comparison", "as_frame"]
