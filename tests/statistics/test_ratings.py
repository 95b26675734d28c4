"""psyop.statistics.ratings: condition means and the ordinal (cumulative-link) model recover a simulated
latent-normal observer; the RM-ANOVA is anova.rm_anova's on participant means; degenerate data are flagged or
refused."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from psyop.errors import UserError
from psyop.statistics import anova
from psyop.statistics.ratings import condition_means, ordinal_model, participant_means, rm_anova

CUTS = np.array([-1.0, -0.3, 0.3, 1.0])  # a 5-point scale
POINTS = len(CUTS) + 1
LATENT_MEAN = {"a": 0.0, "b": 0.5, "c": 1.0}  # latent sd 1: the probit coefficients are 0.5 and 1.0
#: the seeds' mean coefficient lies within this of the true shift (about 4 standard errors of that mean)
COEF_TOLERANCE = 0.05


def _simulate(rng: np.random.Generator, participants: int, trials: int, offset_sd: float = 0.0,
              studies: int = 1) -> pd.DataFrame:
    """Ratings of a latent-normal observer: latent ~ N(mean[condition] + participant offset, 1), cut at CUTS."""
    conds = np.array(list(LATENT_MEAN))
    shape = (studies, participants, len(conds), trials)
    study, person, cond, _ = (a.ravel() for a in np.indices(shape))
    offset = rng.normal(0.0, offset_sd, (studies, participants))[study, person]
    latent = rng.normal(np.array(list(LATENT_MEAN.values()))[cond] + offset, 1.0)
    return pd.DataFrame({"study": study, "participant": person, "cond": conds[cond],
                         "rating": 1 + np.searchsorted(CUTS, latent)})


def _expected_mean_rating(mean: float, sd: float) -> float:
    """E[rating] = 1 + sum_j P(latent > cut_j) for latent ~ N(mean, sd)."""
    return float(1 + stats.norm.cdf((mean - CUTS) / sd).sum())


def _covered(low, high, truth) -> int:
    return int(((np.asarray(low) <= truth) & (truth <= np.asarray(high))).sum())


def test_condition_means_cover_the_expected_mean_rating():
    """200 simulated studies of 10 participants (latent offsets sd 0.3) x 30 trials per condition: the t intervals
    cover the population's mean rating (latent sd sqrt(1 + 0.3^2)) at a rate consistent with 95 %."""
    rng = np.random.default_rng(11)
    studies, tau = 200, 0.3
    s = condition_means(_simulate(rng, 10, 30, tau, studies), ["study", "cond"], points=POINTS)
    assert len(s) == 3 * studies and (s["n"] == 10).all() and (s["n_trials"] == 300).all()
    for cond, mean in LATENT_MEAN.items():
        rows = s[s["cond"] == cond]
        truth = _expected_mean_rating(mean, np.hypot(1.0, tau))
        assert rows["mean"].mean() == pytest.approx(truth, abs=0.04)  # about 4 standard errors of that mean
        covered = _covered(rows["ci_low"], rows["ci_high"], truth)
        assert stats.binomtest(covered, studies, 0.95).pvalue > 0.001, (cond, covered)


def test_ordinal_model_recovers_condition_effects_and_cut_points_within_their_cis():
    """150 seeded data sets (4 participants x 100 trials per condition, probit): each coefficient's and cut point's
    95 % Wald interval covers the truth at a rate consistent with 95 % (binomial test p > 0.001)."""
    seeds = range(150)
    coefs, cuts = [], []
    for seed in seeds:
        fit = ordinal_model(_simulate(np.random.default_rng(seed), 4, 25), ["cond"], POINTS)
        assert fit.converged and fit.flags == ""
        coefs.append(fit.coefficients.set_index("term")[["estimate", "ci_low", "ci_high"]])
        cuts.append(fit.thresholds[["estimate", "ci_low", "ci_high"]].to_numpy())
    for term, truth in (("cond=b", 0.5), ("cond=c", 1.0)):
        rows = pd.DataFrame([c.loc[term] for c in coefs])
        assert rows["estimate"].mean() == pytest.approx(truth, abs=COEF_TOLERANCE)
        covered = _covered(rows["ci_low"], rows["ci_high"], truth)
        assert stats.binomtest(covered, len(seeds), 0.95).pvalue > 0.001, (term, covered)
    cut = np.stack(cuts)  # seed x cut x (estimate, low, high)
    for j, truth in enumerate(CUTS):
        covered = _covered(cut[:, j, 1], cut[:, j, 2], truth)
        assert stats.binomtest(covered, len(seeds), 0.95).pvalue > 0.001, (j, covered)


def test_ordinal_model_tables_and_statsmodels_cut_points():
    from statsmodels.miscmodels.ordinal_model import OrderedModel

    t = _simulate(np.random.default_rng(3), 3, 20)
    fit = ordinal_model(t, ["cond"], POINTS, link="logit", reference="b", ci_level=0.9)
    assert list(fit.coefficients["term"]) == ["cond=a", "cond=c"] and fit.reference == "b"
    assert list(fit.thresholds["cut"]) == ["1|2", "2|3", "3|4", "4|5"] and fit.categories_used == (1, 2, 3, 4, 5)
    exog = pd.DataFrame({"a": (t["cond"] == "a").astype(float), "c": (t["cond"] == "c").astype(float)})
    model = OrderedModel(t["rating"].to_numpy(), exog, distr="logit")
    ref = model.fit(method="bfgs", disp=False, maxiter=2000)
    np.testing.assert_allclose(fit.coefficients["estimate"], ref.params.to_numpy()[:2], rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(fit.thresholds["estimate"], model.transform_threshold_params(ref.params)[1:-1],
                               rtol=1e-6, atol=1e-6)
    assert fit.log_likelihood == pytest.approx(ref.llf)
    z90 = stats.norm.ppf(0.95)
    row = fit.coefficients.iloc[0]
    assert row["ci_high"] - row["estimate"] == pytest.approx(z90 * row["se"])
    offsets = ordinal_model(t, ["cond"], POINTS, participant_offsets=True)
    assert list(offsets.coefficients["term"]) == ["cond=b", "cond=c", "participant=1", "participant=2"]


def test_unused_categories_and_separation_are_flagged_not_silent():
    t = _simulate(np.random.default_rng(4), 3, 20)
    fit = ordinal_model(t[t["rating"] != 3], ["cond"], 7)
    assert fit.flags == "unused_categories" and "3, 6, 7" in fit.flag_text
    assert list(fit.thresholds["cut"]) == ["1|2", "2|4", "4|5"]
    top = t.assign(rating=np.where(t["cond"] == "c", POINTS, t["rating"]))
    assert "separation" in ordinal_model(top, ["cond"], POINTS).flags.split(";")


def test_ordinal_model_refuses_what_it_cannot_fit():
    t = _simulate(np.random.default_rng(5), 2, 10)
    with pytest.raises(UserError, match="single level"):
        ordinal_model(t[t["cond"] == "a"], ["cond"], POINTS)
    with pytest.raises(UserError, match="at least one condition"):
        ordinal_model(t, [], POINTS)
    with pytest.raises(UserError, match="two categories"):
        ordinal_model(t.assign(rating=2), ["cond"], POINTS)
    with pytest.raises(UserError, match="link"):
        ordinal_model(t, ["cond"], POINTS, link="cauchit")
    with pytest.raises(UserError, match=r"1\.\.4"):
        ordinal_model(t, ["cond"], 4)
    with pytest.raises(UserError, match="whole scale points"):
        participant_means(t.assign(rating=t["rating"] + 0.5))
    with pytest.raises(UserError, match="reference"):
        ordinal_model(t, ["cond"], POINTS, reference="z")


def test_several_condition_factors_are_crossed_into_cells():
    t = _simulate(np.random.default_rng(6), 2, 20)
    t["block"] = np.where(t.index % 2 == 0, "first", "second")
    fit = ordinal_model(t, ["cond", "block"], POINTS)
    assert fit.condition == "condition_cell" and fit.reference == "cond=a, block=first"
    assert len(fit.coefficients) == 5


def test_rm_anova_is_anova_rm_anova_on_participant_means():
    t = _simulate(np.random.default_rng(8), 8, 10, offset_sd=0.5)
    result = rm_anova(t, ["cond"], points=POINTS)
    direct = anova.rm_anova(participant_means(t, ["cond"]), "rating", ["cond"])
    pd.testing.assert_frame_equal(result.table, direct.table)
    assert result.effect("cond")["p_gg"] < 0.05
    with pytest.raises(UserError, match="single level"):
        rm_anova(t.assign(block="x"), ["cond", "block"])
    with pytest.raises(UserError, match="one or two"):
        rm_anova(t, [])


def test_condition_means_flag_a_single_participant():
    s = condition_means(_simulate(np.random.default_rng(9), 1, 5), ["cond"])
    assert (s["flags"] == "n_below_2").all() and s["ci_low"].isna().all()
