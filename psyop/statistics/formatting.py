"""Each test in the paper's written form, e.g. ``F(1.70, 30.65) = 17.98, p < 0.0001, eps = 0.85``."""

from __future__ import annotations

import math
from collections.abc import Mapping

from psyop.statistics.regression import ConditionComparison, LinearFit, MixedComparison


def format_p(p: float) -> str:
    """'p < 0.0001', 'p < 0.001', or 'p = 0.64' / 'p = 0.012' (two significant digits)."""
    if not math.isfinite(p):
        return "p = n/a"
    if p < 0.0001:
        return "p < 0.0001"
    if p < 0.001:
        return "p < 0.001"
    return f"p = {p:.2g}" if p >= 0.01 else f"p = {p:.3f}"


def _df(value: float) -> str:
    return f"{value:.0f}" if abs(value - round(value)) < 1e-9 else f"{value:.2f}"


def _low_df(df: float, what: str = "error") -> str:
    from psyop.statistics.small_sample import low_df_note

    note = low_df_note(float(df), what)
    return f" [{note}]" if note else ""


def format_anova(row: Mapping) -> str:
    """One ANOVA effect. GG-corrected df and p, with eps, when eps < 1; plain otherwise.
    A degenerate row (``status`` other than 'ok') is spelled out, not given numbers. Fewer than
    ``small_sample.MIN_RELIABLE_DF`` error df (e.g. F(1, 1)) append a LOW DF flag."""
    return _format_anova(row) + (_low_df(row["df2"]) if row.get("status", "ok") != "zero_error_variance" else "")


def _format_anova(row: Mapping) -> str:
    status = row.get("status", "ok") if hasattr(row, "get") else "ok"
    if status == "zero_error_variance":
        return f"not testable: zero error variance (F undefined; F({_df(row['df1'])}, {_df(row['df2'])}))"
    if status == "eps_undefined":
        return (f"F({_df(row['df1'])}, {_df(row['df2'])}) = {row['F']:.2f}, {format_p(row['p_unc'])} uncorrected; "
                "GG epsilon undefined")
    eps = float(row["eps_gg"])
    if eps < 1.0:
        return (f"F({_df(row['df1_gg'])}, {_df(row['df2_gg'])}) = {row['F']:.2f}, "
                f"{format_p(row['p_gg'])}, eps = {eps:.2f}")
    return f"F({_df(row['df1'])}, {_df(row['df2'])}) = {row['F']:.2f}, {format_p(row['p_unc'])}"


def format_ttest(row: Mapping) -> str:
    """A Bonferroni-corrected paired t-test row from :func:`psyop.statistics.anova.posthoc_paired`."""
    if (row.get("status", "ok") if hasattr(row, "get") else "ok") == "zero_variance":
        return f"not testable: the differences have zero variance (df = {_df(row['dof'])})"
    return (f"t({_df(row['dof'])}) = {row['T']:.2f}, {format_p(row['p_bonf'])} (Bonferroni x{int(row['m'])})"
            + _low_df(row["dof"]))


def format_binomial(row: Mapping) -> str:
    """A one-tailed binomial test row from :mod:`psyop.statistics.binomial`."""
    return (f"{100 * row['proportion']:.1f}% ({row['k']}/{row['n']}), {format_p(row['p'])}, "
            f"one-tailed binomial test")


def format_linear_fit(fit: LinearFit, unit: str = "") -> str:
    """Slope and intercept with their 95 % CIs, R^2, n and the residual df (n - 2) of the t-tests;
    fewer than ``small_sample.MIN_RELIABLE_DF`` residual df append a LOW DF flag."""
    u = f" {unit}" if unit else ""
    df = fit.n - 2
    return (f"slope = {fit.slope:.3f} [{fit.slope_ci_low:.3f}, {fit.slope_ci_high:.3f}], "
            f"intercept = {fit.intercept:.3f}{u} [{fit.intercept_ci_low:.3f}, {fit.intercept_ci_high:.3f}], "
            f"R^2 = {fit.r2:.2f}, n = {fit.n}, df = {df}" + _low_df(df, "residual"))


def format_condition_comparison(c: ConditionComparison) -> str:
    return (f"{c.other} vs {c.reference}: intercept difference = {c.intercept_diff:.3f} ({format_p(c.intercept_diff_p)}), "
            f"slope difference = {c.slope_diff:.3f} ({format_p(c.slope_diff_p)}); "
            f"joint F({c.joint_df1}, {c.joint_df2}) = {c.joint_F:.2f}, {format_p(c.joint_p)}")


def format_joint_test(m: MixedComparison) -> str:
    """The joint test of both differences with its df: 'chi2(2) = 0.85' or 'F(2, 1.31) = 2.10 (HTZ)'."""
    if m.joint_test == "Wald chi2":
        return f"joint Wald chi2({m.joint_df}) = {m.joint_chi2:.2f}"
    suffix = " (HTZ)" if m.joint_test == "HTZ F" else ""
    return f"joint F({m.joint_df}, {_df(m.joint_df_denom)}) = {m.joint_statistic:.2f}{suffix}"


def format_mixed_comparison(m: MixedComparison) -> str:
    """The subject-aware reach test: method, differences, the joint test with its df, any fallback reason
    and every small-sample flag."""
    out = (f"{m.other} vs {m.reference}: intercept difference = {m.intercept_diff:.3f} ({format_p(m.intercept_diff_p)}), "
           f"slope difference = {m.slope_diff:.3f} ({format_p(m.slope_diff_p)}); {format_joint_test(m)}, "
           f"{format_p(m.joint_p)} [{m.method}; {m.n_subjects} participants, {m.n} reaches]")
    out += f" (fallback: {m.fallback_reason})" if m.fallback_reason else ""
    return out + (f" [{m.flag_text}]" if m.flag_text else "")


def format_threshold(row: Mapping) -> str:
    """A threshold with its 95 % interval, e.g. '0.36 D [0.28, 0.45]'."""
    return f"{row['threshold_D']:.2f} D [{row['threshold_ci_low_D']:.2f}, {row['threshold_ci_high_D']:.2f}]"
