"""Censored thresholds: the Tobit rule recovers the group mean where the drop rule is biased."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from psyop.statistics.censored import censoring_of, tobit_fit, tobit_mean


def test_without_censoring_the_tobit_mean_is_the_sample_mean_and_sigma_the_ml_sd():
    y = np.array([0.31, 0.52, 0.44, 0.29, 0.61, 0.38])
    fit = tobit_mean(y, np.zeros(6, int))
    assert fit.coef[0] == pytest.approx(y.mean(), abs=1e-6)
    assert fit.sigma == pytest.approx(y.std(ddof=0), rel=1e-4)
    assert fit.se[0] == pytest.approx(y.std(ddof=0) / np.sqrt(6), rel=1e-3)


def test_recovery_the_censored_rule_is_unbiased_where_the_drop_rule_is_biased():
    """300 simulated groups of 12 thresholds ~ N(0.40, 0.15) D, tested from 0.30 D up to 0.70 D:
    about 25 % are censored below and 3 % above. Tolerance: mean bias under 0.015 D for the Tobit
    rule (its Monte Carlo sd of the mean bias is about 0.003 D); the drop rule is biased by more than 0.04 D."""
    rng = np.random.default_rng(29)
    lo, hi, true = 0.30, 0.70, 0.40
    tobit, drop = [], []
    for _ in range(300):
        t = rng.normal(true, 0.15, 12)
        side = np.where(t < lo, -1, np.where(t > hi, 1, 0))
        y = np.clip(t, lo, hi)
        tobit.append(tobit_mean(y, side).coef[0])
        drop.append(t[side == 0].mean())
    assert abs(np.mean(tobit) - true) < 0.015
    assert np.mean(drop) - true > 0.04


def test_censored_slope_is_recovered_where_the_drop_rule_flattens_it():
    rng = np.random.default_rng(7)
    x = np.repeat([0.0, 0.5, 1.0, 1.5], 6)
    slopes_t, slopes_d = [], []
    for _ in range(150):
        t = 0.25 + 0.11 * x + rng.normal(0, 0.1, len(x))
        side = np.where(t < 0.25, -1, 0)
        y = np.maximum(t, 0.25)
        X = np.column_stack([np.ones_like(x), x])
        slopes_t.append(tobit_fit(y, X, side, ("intercept", "slope")).coef[1])
        keep = side == 0
        slopes_d.append(np.polyfit(x[keep], t[keep], 1)[0])
    assert abs(np.mean(slopes_t) - 0.11) < 0.01
    assert 0.11 - np.mean(slopes_d) > 0.02


def test_censoring_of_enters_censored_fits_at_their_bound_and_leaves_ambiguous_ones_out():
    fits = pd.DataFrame({
        "status": ["ok", "censored_below", "censored_above", "bimodal", "lapse_at_bound"],
        "threshold_D": [0.4, np.nan, np.nan, np.nan, np.nan],
        "threshold_bound_D": [np.nan, 0.1, 1.0, np.nan, 1.0],
    })
    rows, left = censoring_of(fits)
    assert rows["side"].tolist() == [0, -1, 1, 1]
    assert rows["y"].tolist() == [0.4, 0.1, 1.0, 1.0]
    assert left == {"bimodal": 1}


def test_too_few_uncensored_values_is_refused_with_a_message():
    with pytest.raises(ValueError, match="uncensored"):
        tobit_mean(np.array([0.1, 0.1, 0.4]), np.array([-1, -1, 0]))


def test_a_linear_fit_with_few_residual_df_is_flagged_low_df_and_states_its_df():
    from psyop.statistics.formatting import format_linear_fit
    from psyop.statistics.regression import linear_fit

    few = pd.DataFrame({"x": [0.0, 0.5, 1.0, 1.5, 2.0], "y": [0.30, 0.36, 0.41, 0.52, 0.55]})
    text = format_linear_fit(linear_fit(few, "x", "y"), "D")
    assert "df = 3" in text and "LOW DF: 3 residual df < 4" in text
    many = pd.concat([few] * 3, ignore_index=True)
    text = format_linear_fit(linear_fit(many, "x", "y"), "D")
    assert "df = 13" in text and "LOW DF" not in text


def test_repeated_fits_of_few_participants_get_clustered_errors_on_participant_df_flagged_low():
    """Three participants x two conditions: six fits but three independent observers. The report's Tobit
    mean uses participant-clustered SEs with t on 2 df and says LOW DF, never df = 5 as if the six fits
    were independent; one fit per participant stays the independent model."""
    from psyop.statistics.censored import censored_report

    fits = pd.DataFrame({"participant": ["S1", "S1", "S2", "S2", "S3", "S3"], "c": [1, 2] * 3,
                         "status": ["ok", "ok", "censored_below", "ok", "ok", "ok"],
                         "threshold_D": [0.41, 0.52, np.nan, 0.38, 0.47, 0.60],
                         "threshold_bound_D": [np.nan, np.nan, 0.3, np.nan, np.nan, np.nan]})
    report = censored_report(fits, "c", "D")
    assert report["mean"]["n_clusters"] == 3 and report["mean"]["df_interval"] == 2 and report["mean"]["low_df"]
    assert "df = 2]" in report["text_mean"] and "participant-clustered SEs (3 participants" in report["text_mean"]
    assert "LOW DF: 2 participant df < 4" in report["text_mean"]
    one_each = censored_report(fits.drop_duplicates("participant"), "c", "D")
    assert one_each["mean"]["n_clusters"] == 0 and "fits treated as independent" in one_each["text_mean"]


def test_recovery_with_repeated_fits_per_participant_clustered_cell_means_unbiased_and_covering():
    """The design the analysis scripts meet: 12 participants x 3 conditions (means 0.35, 0.45, 0.55 D),
    a participant effect (sd 0.10 D) shared by a participant's three fits plus fit noise (sd 0.08 D),
    levels tested from 0.35 D (the floor: about 50 %, 22 % and 6 % of fits censored below) to 0.90 D;
    150 seeded groups. Tolerance: each Tobit cell mean's average bias under 0.015 D (Monte Carlo sd of
    that average about 0.004 D; measured -0.006 to 0.002 D over seeds 29-31); the drop rule's biased up
    by more than 0.08 D at the floor and 0.03 D next to it (measured 0.10 and 0.047). The participant-
    clustered 95 % intervals (t on 11 df) cover each true mean in 88-100 % of groups (measured 93-98 %)."""
    from psyop.statistics.censored import censored_condition_means

    rng = np.random.default_rng(29)
    means, lo, hi, g = np.array([0.35, 0.45, 0.55]), 0.35, 0.90, 12
    tobit, drop, cover, df_interval = [], [], [], set()
    for _ in range(150):
        t = means[None, :] + rng.normal(0, 0.10, g)[:, None] + rng.normal(0, 0.08, (g, 3))
        rows = pd.DataFrame({"participant": np.repeat([f"S{i:02d}" for i in range(g)], 3), "c": np.tile([1, 2, 3], g),
                             "t": t.ravel()})
        rows["side"] = np.where(rows["t"] < lo, -1, np.where(rows["t"] > hi, 1, 0))
        rows["y"] = rows["t"].clip(lo, hi)
        fit = censored_condition_means(rows, "c", rows["participant"].to_numpy())
        tobit.append(fit.coef)
        drop.append(rows[rows["side"] == 0].groupby("c")["t"].mean().to_numpy())
        cover.append((np.array(fit.ci_low) <= means) & (means <= np.array(fit.ci_high)))
        df_interval.add(fit.df_interval)
    assert df_interval == {g - 1}
    assert np.all(np.abs(np.mean(tobit, axis=0) - means) < 0.015)
    bias_drop = np.mean(drop, axis=0) - means
    assert bias_drop[0] > 0.08 and bias_drop[1] > 0.03
    assert np.all((np.mean(cover, axis=0) >= 0.88) & (np.mean(cover, axis=0) <= 1.0))


def test_recovery_through_psychometric_fits_the_censored_rule_recovers_what_the_drop_rule_overstates():
    """End to end from trials: 80 simulated 2AFC observers (75 %-correct thresholds ~ N(0.40, 0.15) D, sd
    0.1 D, lapse 0.02), 5 levels 0.30-0.90 D x 20 trials each, fitted by psyop's psignifit pipeline; the fit
    statuses (not the true values) decide which are censored (about 25 % censored_below). Tolerance: the
    Tobit mean within 0.02 D of the observers' true mean (measured -0.008 to +0.005 D over seeds 1-6, 29),
    the true mean inside its 95 % interval; the drop rule (usable fits only) above it by more than 0.035 D
    (measured 0.053 to 0.071 D)."""
    from scipy.stats import norm

    from psyop.statistics.psychometric import USABLE_STATUSES, fit_psychometric

    rng = np.random.default_rng(29)
    levels, n, lapse, sd = np.array([0.30, 0.45, 0.60, 0.75, 0.90]), 20, 0.02, 0.1
    z75 = norm.ppf(0.25 / (0.5 - lapse))  # 0.5 + (0.5 - lapse) * Phi(z75) = 0.75
    true = rng.normal(0.40, 0.15, 80)
    rows = []
    for threshold in true:
        pc = 0.5 + (0.5 - lapse) * norm.cdf((levels - (threshold - sd * z75)) / sd)
        fit = fit_psychometric(np.column_stack([levels, rng.binomial(n, pc), np.full(len(levels), n)]))
        rows.append({"status": fit.status, "threshold_D": fit.threshold_D, "threshold_bound_D": fit.threshold_bound_D})
    fits = pd.DataFrame(rows)
    entered, left_out = censoring_of(fits)
    assert left_out == {} and len(entered) == len(fits) and (fits["status"] == "censored_below").mean() > 0.15
    tobit = tobit_mean(entered["y"].to_numpy(), entered["side"].to_numpy())
    assert abs(tobit.coef[0] - true.mean()) < 0.02 and tobit.ci_low[0] <= true.mean() <= tobit.ci_high[0]
    dropped = fits.loc[fits["status"].isin(USABLE_STATUSES), "threshold_D"].mean()
    assert dropped - true.mean() > 0.035
