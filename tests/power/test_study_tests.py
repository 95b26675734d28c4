"""Each study's reported tests, on trial tables drawn by psyop.statistics.simulate (no sessions)."""

import math
from pathlib import Path

import numpy as np

from psyop.power.study_tests import ordinal_tests, reach_tests, realism_tests, study_tests
from psyop.protocol import load_protocol
from psyop.statistics import simulate

ROOT = Path(__file__).resolve().parents[2]


def test_every_study_kind_reports_its_tests() -> None:
    rng = np.random.default_rng(3)
    ordinal = ordinal_tests(simulate.simulate_ordinal(rng, 6))
    assert [o.test for o in ordinal[:3]] == ["rm-ANOVA: mode", "rm-ANOVA: separation_D", "rm-ANOVA: mode * separation_D"]
    assert len(ordinal) == 3 + 6 and all(0 <= o.p <= 1 for o in ordinal)
    reach = reach_tests(simulate.simulate_reach(rng, 5))
    assert [o.test for o in reach] == [f"{kind}: {what} difference" for kind in ("mixed model", "pooled regression")
                                       for what in ("slope", "intercept", "joint")]
    realism = realism_tests(simulate.simulate_realism(rng, 5))
    assert realism[0].test == "binomial: ocular over conventional" and realism[0].p < 0.05
    protocol = load_protocol(ROOT / "protocols" / "discrimination.yaml")
    two = study_tests(protocol, simulate.simulate_discrimination(rng, 4, slope=0.5))
    assert [o.test for o in two] == ["rm-ANOVA: threshold ~ offset_D", "regression slope: threshold ~ offset_D"]
    assert two[1].p < 0.05  # a large slope is found


def test_a_test_that_cannot_be_computed_says_why() -> None:
    rng = np.random.default_rng(4)
    protocol = load_protocol(ROOT / "protocols" / "detection.yaml")
    outcomes = study_tests(protocol, simulate.simulate_detection(rng, 1))
    anova = outcomes[0]
    assert math.isnan(anova.p) and anova.note.startswith("not computed:")


def test_reach_power_reports_the_analysis_primary_mixed_model_and_the_pooled_one_beside_it() -> None:
    """The primary reach test is the MixedLM of analysis/fig_egocentric_reach.py, not the pooled OLS."""
    from psyop.statistics.regression import condition_interaction, mixed_condition_comparison

    rng = np.random.default_rng(8)
    trials = simulate.simulate_reach(rng, 6, slope_sd=0.15, subject_sd=0.08)
    trials["reach_fraction"] = trials["reach_m"] / trials["arm_reach_m"]
    outcomes = {o.test: o for o in reach_tests(trials)}
    mixed = mixed_condition_comparison(trials, "target_fraction", "reach_fraction", "rendering", reference="disabled")
    pooled = condition_interaction(trials, "target_fraction", "reach_fraction", "rendering", "disabled")
    assert outcomes["mixed model: slope difference"].p == mixed.slope_diff_p
    assert outcomes["mixed model: intercept difference"].p == mixed.intercept_diff_p
    assert outcomes["mixed model: joint difference"].p == mixed.joint_p
    assert outcomes["pooled regression: joint difference"].p == pooled.joint_p
    assert mixed.joint_p != pooled.joint_p
    assert list(outcomes)[0] == "mixed model: slope difference"


def test_a_mixed_model_fallback_is_flagged_and_counted() -> None:
    from psyop.power.replicate import ReplicationResult
    from psyop.power.summary import power_table

    rng = np.random.default_rng(9)
    outcomes = reach_tests(simulate.simulate_reach(rng, 2))  # two participants: no mixed model, clustered OLS
    primary = [o for o in outcomes if o.test.startswith("mixed model")]
    assert primary and all(o.flag.startswith("fallback to OLS") for o in primary)
    # CR2 over 2 clusters: each difference has a (low-df) p; both jointly cannot be tested (2 clusters,
    # 2 contrasts: a singular covariance), NaN rather than a number
    assert all(not math.isnan(o.p) for o in primary if o.test != "mixed model: joint difference")
    assert math.isnan(next(o.p for o in primary if o.test == "mixed model: joint difference"))
    assert all(o.flag == "" for o in outcomes if o.test.startswith("pooled"))
    table = power_table([ReplicationResult(2, 0, tuple(outcomes), 1)])
    assert table.set_index("test").loc["mixed model: joint difference", "n_flagged"] == 1


def test_power_fits_without_the_unread_estimates_give_identical_p_values_thresholds_and_statuses() -> None:
    """power_fit_options skips the free-eta posterior and the deviance bootstrap: every p value, threshold,
    interval, status and flag equals the one the full analysis options (analysis/fit_psychometric.py) give."""
    from psyop.power.study_tests import power_fit_options, two_interval_tests
    from psyop.statistics.psychometric import FitOptions, fit_psychometric_table

    full = FitOptions()
    assert power_fit_options() == FitOptions(estimate_eta=False, n_bootstrap=0)
    rng = np.random.default_rng(21)
    cases = [("detection", simulate.simulate_detection(rng, 3)), ("discrimination", simulate.simulate_discrimination(rng, 3, slope=0.4))]
    for name, trials in cases:
        protocol = load_protocol(ROOT / "protocols" / f"{name}.yaml")
        fast, reference = two_interval_tests(protocol, trials), two_interval_tests(protocol, trials, full)
        assert [o.test for o in fast] == [o.test for o in reference]
        assert [(o.p, o.note, o.flag) for o in fast] == [(o.p, o.note, o.flag) for o in reference]
        assert all(not math.isnan(o.p) for o in fast)
        condition = "back_D" if name == "detection" else "offset_D"
        groups = ["participant", condition]
        a = fit_psychometric_table(trials, "level_D", groups, options=power_fit_options())
        b = fit_psychometric_table(trials, "level_D", groups, options=full)
        same = ["status", "flags", "threshold_D", "threshold_ci_low_D", "threshold_ci_high_D", "threshold_bound_D",
                "width_D", "location_D", "lapse", "deviance"]
        assert a[groups + same].equals(b[groups + same])
        assert a["eta"].isna().all() and a["deviance_p"].isna().all()  # the skipped estimates are absent, not made up
        assert b["eta"].notna().all() and b["deviance_p"].notna().all()
