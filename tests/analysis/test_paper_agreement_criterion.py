"""results/summary.md's "agrees with the paper": the same conclusion, not only an overlapping interval."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

ANALYSIS = Path(__file__).resolve().parents[2] / "analysis"


def _paper_values():
    if str(ANALYSIS) not in sys.path:
        sys.path.insert(0, str(ANALYSIS))
    return importlib.import_module("paper_values")


def _discrimination(slope: float, low: float, high: float) -> dict:
    return {"linear_fit": {"slope": slope, "slope_ci_low": low, "slope_ci_high": high,
                           "intercept": 0.38, "intercept_ci_low": 0.3, "intercept_ci_high": 0.5}}


def _slope_row(payload: dict) -> dict:
    rows = _paper_values().rows_for({"discrimination_fit": payload})
    return next(r for r in rows if r["statistic"] == "slope of threshold vs offset")


def test_a_slope_interval_that_includes_zero_does_not_reproduce_the_papers_positive_slope():
    """The issue's case: 0.032 [-0.076, 0.141] holds 0.11 but also 0, so the paper's finding (thresholds
    increase with offset) is not reproduced: the value check passes, the conclusion check fails."""
    row = _slope_row(_discrimination(0.032, -0.076, 0.141))
    assert row["agrees"] == "no"
    assert "value passed" in row["criteria"] and "conclusion failed" in row["criteria"]
    assert "includes 0" in row["criteria"]


def test_a_positive_slope_whose_interval_holds_the_papers_value_agrees():
    row = _slope_row(_discrimination(0.12, 0.05, 0.19))
    assert row["agrees"] == "yes" and "conclusion passed" in row["criteria"]


def test_a_significant_positive_slope_that_excludes_the_papers_value_fails_on_value():
    row = _slope_row(_discrimination(0.5, 0.4, 0.6))
    assert row["agrees"] == "no" and "value failed" in row["criteria"]


def test_a_significant_posthoc_in_the_wrong_direction_fails():
    pv = _paper_values()
    post = [{"separation_D": 1.0, "A": "ocular", "B": "conventional", "mean_A": 0.6, "mean_B": 0.8, "dof": 18,
             "T": -4.0, "p_bonf": 0.001, "m": 3}]
    rows = pv.rows_for({"ordinal": {"posthoc": post, "anova": [], "summary": {}}})
    row = next(r for r in rows if r["statistic"] == "1 D: ocular parallax vs conventional")
    assert row["agrees"] == "no" and "psyop conventional higher" in row["criteria"]


def test_a_study_not_run_is_not_judged():
    row = next(r for r in _paper_values().rows_for({}) if r["study"] == "realism")
    assert row["agrees"] == "n/a" and "study not run" in row["criteria"]


def test_a_cr2_fallback_is_named_with_its_df_and_flags_and_an_untestable_joint_is_not_judged():
    pv = _paper_values()
    comparison = {"joint_df1": 2, "joint_df2": 100, "joint_F": 1.0, "joint_p": 0.4}
    mixed = {"method": "OLS with CR2 participant-clustered standard errors (Satterthwaite t, HTZ F; ...)",
             "joint_test": "HTZ F", "joint_chi2": 3.5, "joint_statistic": 0.87, "joint_df_denom": 0.99, "joint_p": 0.6,
             "flags": "few_participants;low_df", "flag_text": "LOW DF", "fallback_reason": "no mixed model"}
    row = next(r for r in pv.rows_for({"egocentric": {"mixed": mixed, "comparison": comparison, "fits": []}})
               if r["statistic"].startswith("enabled vs disabled"))
    assert "F(2, 0.99) = 0.87 (HTZ F)" in row["psyop"] and "low_df" in row["psyop"] and "chi2" not in row["psyop"]
    mixed = {**mixed, "joint_p": float("nan")}
    row = next(r for r in pv.rows_for({"egocentric": {"mixed": mixed, "comparison": comparison, "fits": []}})
               if r["statistic"].startswith("enabled vs disabled"))
    assert row["agrees"] == "n/a"
