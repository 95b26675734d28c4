"""The tests a study reports, computed on one simulated study's trials with the same
``psyop.statistics`` calls the analysis scripts (analysis/*.py) make.

- two-interval threshold studies (detection, discrimination): psignifit fits per participant and
  condition (analysis/fit_psychometric.py options, less the free-eta posterior and the deviance
  bootstrap no test reads: :func:`power_fit_options`), then the rm-ANOVA of thresholds over the
  condition (analysis/fig_detection_thresholds.py) and the linear slope of threshold against the
  condition (analysis/fig_discrimination_thresholds.py); flagged fits are left out as there;
- left/right nearer (ordinal): rm-ANOVA of proportion correct over mode x separation and the
  Bonferroni post-hoc tests per separation (analysis/fig_ordinal_depth.py);
- pairwise preference (realism): one-tailed binomial tests per pair (analysis/fig_realism.py);
- reach (egocentric): the primary test, a mixed model with participants random (slope, intercept
  and joint differences), and beside it the paper's pooled multiple regression, named as such
  (analysis/fig_egocentric_reach.py).
A test that cannot be computed (too few complete participants, ...) gets p = nan and the reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import pandas as pd

from psyop.errors import UserError
from psyop.protocol.model import Protocol
from psyop.protocol.response import TwoIntervalResponse

if TYPE_CHECKING:
    from psyop.statistics.psychometric import FitOptions

REALISM_PAIRS = [("ocular", "conventional"), ("reversed", "conventional"), ("ocular", "reversed")]


@dataclass(frozen=True)
class TestOutcome:
    test: str
    p: float
    note: str = ""  # why p is nan
    flag: str = ""  # the p is a number, but from a fallback the analysis flags (e.g. a mixed model's)

    __test__ = False  # not a pytest class

    def same_as(self, other: TestOutcome) -> bool:
        """Equal test, note and flag, and the same p value (two NaN p values are the same: a refused test)."""
        return ((self.test, self.note, self.flag) == (other.test, other.note, other.flag)
                and (self.p == other.p or (math.isnan(self.p) and math.isnan(other.p))))


def same_outcomes(a: tuple[TestOutcome, ...] | list[TestOutcome], b: tuple[TestOutcome, ...] | list[TestOutcome]) -> bool:
    """Two replications' outcomes are the same, test by test (:meth:`TestOutcome.same_as`)."""
    return len(a) == len(b) and all(x.same_as(y) for x, y in zip(a, b))


def _not_computed(test: str, exc: Exception) -> TestOutcome:
    return TestOutcome(test, math.nan, f"not computed: {exc}")


def _level_factor(protocol: Protocol) -> str:
    """The two-interval response's level factor (the only response kind with thresholds)."""
    response = protocol.response
    assert isinstance(response, TwoIntervalResponse)  # study_tests sends two_interval protocols only
    return response.level_factor


def condition_factors(protocol: Protocol) -> list[str]:
    """The design's factors other than the level factor, in the protocol's order."""
    level = _level_factor(protocol)
    return [name for name in protocol.design.factors if name != level]


def threshold_condition(protocol: Protocol) -> str:
    """The condition thresholds are compared over: the one factor besides the level factor, or the crossed
    cells of several (psyop.statistics.conditions: analysis/fit_psychometric.py compares the same)."""
    from psyop.statistics.conditions import condition_of

    try:
        return condition_of(condition_factors(protocol))
    except ValueError as exc:
        raise UserError(str(exc), "protocol design") from None


def power_fit_options() -> FitOptions:
    """analysis/fit_psychometric.py's fit options less what power's tests never read: the free-eta
    posterior (``eta``, 72 % of a fit) and the deviance bootstrap (``deviance_p``). Thresholds, their
    intervals and statuses are computed exactly as there (tests/power/test_study_tests.py checks
    the p values, thresholds and statuses are identical with the full options)."""
    from psyop.statistics.psychometric import FitOptions

    return FitOptions(estimate_eta=False, n_bootstrap=0)


def two_interval_tests(protocol: Protocol, trials: pd.DataFrame,
                       options: FitOptions | None = None) -> list[TestOutcome]:
    """The rm-ANOVA of thresholds over the condition and, when its levels are numbers, the slope of threshold
    on it; ``options``: the psignifit fit options (default :func:`power_fit_options`). The condition is one
    factor of numbers or words, or the crossed cells of several (:func:`threshold_condition`)."""
    from psyop.statistics.anova import rm_anova
    from psyop.statistics.psychometric import fit_psychometric_table, usable_for_analysis
    from psyop.statistics.regression import linear_fit

    from psyop.statistics.conditions import describe, numeric_levels, with_condition

    condition = threshold_condition(protocol)
    level = _level_factor(protocol)
    options = power_fit_options() if options is None else options
    groups = ["participant", condition]
    trials = with_condition(trials, condition_factors(protocol))
    # only the columns the fit reads: boolean selections of the whole trial table (38 columns, string
    # ones among them) were 30 % of a detection replication's analysis; the fit table is the same
    fits = fit_psychometric_table(trials[[*groups, level, "correct"]], level, groups, options=options, n_jobs=1)
    clean, _ = usable_for_analysis(fits)  # the documented status rule (censored etc. left out)
    out = []
    name = f"rm-ANOVA: threshold ~ {describe(condition_factors(protocol))}"
    try:
        out.append(TestOutcome(name, float(rm_anova(clean, "threshold_D", condition).table.iloc[0]["p_gg"])))
    except ValueError as exc:
        out.append(_not_computed(name, exc))
    if not numeric_levels(trials[condition]):
        return out  # levels of words (or crossed cells): no slope over them, as the analysis reports none
    name = f"regression slope: threshold ~ {condition}"
    try:
        out.append(TestOutcome(name, float(linear_fit(clean, condition, "threshold_D").slope_p)))
    except (ValueError, ZeroDivisionError) as exc:
        out.append(_not_computed(name, exc))
    return out


def ordinal_tests(trials: pd.DataFrame) -> list[TestOutcome]:
    from psyop.statistics.anova import cell_means, posthoc_paired, rm_anova

    cells = cell_means(trials, "correct", ["mode", "separation_D"])
    out = []
    try:
        for _, r in rm_anova(cells, "correct", ["mode", "separation_D"]).table.iterrows():
            out.append(TestOutcome(f"rm-ANOVA: {r['effect']}", float(r["p_gg"])))
    except ValueError as exc:
        out.append(_not_computed("rm-ANOVA", exc))
    for _, r in posthoc_paired(cells, "correct", "mode", by="separation_D").iterrows():
        out.append(TestOutcome(f"post-hoc at {r['separation_D']:g} D: {r['A']} vs {r['B']}", float(r["p_bonf"])))
    return out


def realism_tests(trials: pd.DataFrame) -> list[TestOutcome]:
    from psyop.statistics.binomial import pairwise_preferences

    prefs = pairwise_preferences(trials, REALISM_PAIRS)
    return [TestOutcome(f"binomial: {r['first']} over {r['second']}", float(r["p"])) for _, r in prefs.iterrows()]


REACH_PRIMARY = ("mixed model: slope difference", "mixed model: intercept difference",
                 "mixed model: joint difference")
REACH_POOLED = ("pooled regression: slope difference", "pooled regression: intercept difference",
                "pooled regression: joint difference")


def reach_tests(trials: pd.DataFrame, reference: str = "disabled") -> list[TestOutcome]:
    """The primary test (MixedLM, participants random: ``mixed_condition_comparison``, as
    analysis/fig_egocentric_reach.py) and, beside it, the paper's pooled multiple regression.
    A mixed fit that fell back (random intercept only, or clustered OLS) keeps its p and says so
    in ``flag``, as the analysis reports it."""
    from psyop.statistics.regression import condition_interaction, mixed_condition_comparison

    t = trials.copy()
    if "reach_fraction" not in t:
        t["reach_fraction"] = t["reach_m"] / t["arm_reach_m"]
    t = t[t["reach_fraction"].notna()]
    out: list[TestOutcome] = []
    try:
        m = mixed_condition_comparison(t, "target_fraction", "reach_fraction", "rendering", reference=reference)
    except ValueError as exc:
        out += [_not_computed(n, exc) for n in REACH_PRIMARY]
    else:
        flag = f"fallback to {m.method}: {m.fallback_reason}" if m.fallback_reason else ""
        out += [TestOutcome(n, float(p), note=m.flag_text if math.isnan(p) else "", flag=flag)
                for n, p in zip(REACH_PRIMARY, (m.slope_diff_p, m.intercept_diff_p, m.joint_p))]
    try:
        c = condition_interaction(t, "target_fraction", "reach_fraction", "rendering", reference)
    except ValueError as exc:
        return out + [_not_computed(n, exc) for n in REACH_POOLED]
    return out + [TestOutcome(n, float(p)) for n, p in
                  zip(REACH_POOLED, (c.slope_diff_p, c.intercept_diff_p, c.joint_p))]


def study_tests(protocol: Protocol, trials: pd.DataFrame) -> list[TestOutcome]:
    """Every reported test of the protocol's study on ``trials`` (one simulated study)."""
    kind = protocol.response.kind
    if kind == "two_interval":
        return two_interval_tests(protocol, trials)
    if kind == "left_right_nearer":
        return ordinal_tests(trials)
    if kind == "pairwise_preference":
        return realism_tests(trials)
    if kind == "reach":
        return reach_tests(trials)
    raise UserError(f"no power analysis for response kind {kind!r}", "protocol response")
