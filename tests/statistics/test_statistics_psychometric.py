"""Psychometric fits: parameter recovery at the paper's design, flags, agreement with psignifit."""

from __future__ import annotations

import numpy as np
import pandas as pd
import psignifit
import pytest

from psyop.statistics.psychometric import (
    FitOptions, aggregate_blocks, fit_many, fit_psychometric, fit_psychometric_table,
)
from psyop.statistics.simulate import DETECTION_LEVELS_D, pc_2afc, simulate_detection, true_t75

LEVELS = np.array(DETECTION_LEVELS_D)


def _datasets(rng, n, threshold_D=0.36, sigma_D=0.2, lapse=0.0, n_per_level=15):
    p = pc_2afc(LEVELS, threshold_D, sigma_D, lapse)
    return [np.c_[LEVELS, rng.binomial(n_per_level, p), np.full(len(LEVELS), n_per_level)] for _ in range(n)]


def test_parameter_recovery_detection_design():
    """400 simulated observers (>= 200 asked), 5 levels x 15 trials: bias < 0.02 D, 95 % CI coverage in [0.90, 0.99]."""
    rng = np.random.default_rng(12345)
    truth = true_t75(0.36, 0.2, 0.0)
    fits = fit_many(_datasets(rng, 400), FitOptions(n_bootstrap=0, estimate_eta=False), n_jobs=2)  # no GOF needed here
    est = np.array([f.threshold_D for f in fits])
    lo = np.array([f.threshold_ci_low_D for f in fits])
    hi = np.array([f.threshold_ci_high_D for f in fits])
    assert np.all(np.isfinite(est))
    assert abs(est.mean() - truth) < 0.02
    coverage = np.mean((lo <= truth) & (truth <= hi))
    assert 0.90 <= coverage <= 0.99, coverage
    assert np.all(lo <= est) and np.all(est <= hi)


def test_recovery_with_lapses_uses_the_75_percent_point():
    rng = np.random.default_rng(7)
    truth = true_t75(0.4, 0.15, 0.04)  # the 75 % point moves right when the observer lapses
    fits = fit_many(_datasets(rng, 40, 0.4, 0.15, 0.04, n_per_level=60), FitOptions(n_bootstrap=0, estimate_eta=False), n_jobs=2)
    est = np.array([f.threshold_D for f in fits])
    assert abs(np.median(est) - truth) < 0.03
    assert np.mean([f.lapse for f in fits]) < 0.15


def test_agrees_with_public_psignifit_threshold():
    data = np.array([[0, 8, 15], [0.25, 10, 15], [0.5, 12, 15], [0.75, 14, 15], [1.0, 15, 15]], float)
    ours = fit_psychometric(data, FitOptions(n_bootstrap=0))
    res = psignifit.psignifit(data, experiment_type="2AFC", sigmoid="norm", verbose=False)
    theirs = float(res.threshold(0.75, return_ci=False))
    assert ours.threshold_D == pytest.approx(theirs, abs=0.02)
    assert ours.lapse == pytest.approx(res.parameter_estimate["lambda"], abs=0.03)
    free = fit_psychometric(data, FitOptions(n_bootstrap=0, fixed_eta=None))  # psignifit's own setting
    assert free.threshold_D == pytest.approx(theirs, abs=0.01)
    assert 0.0 <= ours.eta <= 1.0


def test_all_correct_is_flagged():
    data = np.c_[LEVELS, np.full(5, 15), np.full(5, 15)]
    fit = fit_psychometric(data, FitOptions(n_bootstrap=0))
    assert "all_correct" in fit.flags and not fit.ok
    assert "threshold_outside_range" in fit.flags


def test_fewer_than_two_levels_is_flagged_not_raised():
    fit = fit_psychometric(np.array([[0.5, 10, 15]]))
    assert fit.flags == ("fewer_than_two_levels",) and np.isnan(fit.threshold_D)


def test_chance_performance_flags_threshold_outside_range_or_grid_edge():
    data = np.c_[LEVELS, np.full(5, 7), np.full(5, 15)]
    fit = fit_psychometric(data, FitOptions(n_bootstrap=0))
    assert {"threshold_outside_range", "posterior_at_grid_edge"} & set(fit.flags)


def test_deviance_pvalue_is_calibrated_under_the_fitted_model():
    """Data drawn from the curve itself: p < 0.05 about 5 % of the time; a misfit gives small p."""
    rng = np.random.default_rng(3)
    from psyop.statistics.goodness import deviance_test

    p = pc_2afc(LEVELS, 0.36, 0.2, 0.0)
    n = np.full(5, 15)
    pvals = np.array([deviance_test(rng.binomial(n, p), n, p, 500, seed=i).p_value for i in range(400)])
    assert 0.02 <= np.mean(pvals < 0.05) <= 0.09
    bad = deviance_test(np.array([15, 0, 15, 0, 15]), n, p, 500)
    assert bad.p_value < 0.01 and bad.deviance > 20


def test_fit_table_groups_and_counts_missing_responses():
    rng = np.random.default_rng(1)
    trials = simulate_detection(rng, n_subjects=2)
    trials["correct"] = trials["correct"].astype(object)
    trials.loc[trials.index[:3], "correct"] = None
    table = fit_psychometric_table(trials, "level_D", ["participant", "back_D"], options=FitOptions(n_bootstrap=50))
    assert len(table) == 6 and set(table["back_D"]) == {1.0, 2.0, 3.0}
    assert table["n_missing"].sum() == 3
    assert (table["n_trials"] + table["n_missing"] == 75).all()
    assert table["threshold_D"].between(0, 1).all()


def test_aggregate_blocks():
    out = aggregate_blocks(np.array([0.5, 0.0, 0.5, 0.5]), np.array([1, 0, 0, 1]))
    np.testing.assert_array_equal(out, [[0.0, 0, 1], [0.5, 2, 3]])
    assert isinstance(pd.DataFrame(out), pd.DataFrame)
