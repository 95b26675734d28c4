"""Type I error under the null and power under known effects (ANOVA, regression, binomial)."""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.stats import binom

from psyop.statistics.anova import cell_means, rm_anova
from psyop.statistics.binomial import pairwise_preferences
from psyop.statistics.regression import condition_interaction, linear_fit
from psyop.statistics.simulate import simulate_ordinal, simulate_reach, simulate_realism


def _band(n: int, alpha: float = 0.05, tail: float = 1e-4) -> tuple[float, float]:
    """Central binomial interval of a rejection rate over n simulations (two-sided tail)."""
    return binom.ppf(tail, n, alpha) / n, binom.isf(tail, n, alpha) / n


def _null_two_way(rng, n_subjects=12):
    # 3 x 3 within design with NO effects but non-spherical errors: the subject-specific
    # random slope over A makes the uncorrected F liberal; GG must bring it back to ~5 %.
    rows = []
    for s in range(n_subjects):
        u = rng.normal(0, 1)
        slope = rng.normal(0, 1.0)
        for i in range(3):
            for j in range(3):
                rows.append({"participant": f"s{s}", "A": f"a{i}", "B": f"b{j}",
                             "y": u + slope * (i - 1) * (j - 1) + slope * (i - 1) + rng.normal(0, 0.4)})
    return pd.DataFrame(rows)


def test_rm_anova_type_i_error_with_gg_under_non_sphericity():
    rng = np.random.default_rng(2024)
    n = 150  # benchmarks/bench_statistics_calibration.py runs 1,000
    tables = [rm_anova(_null_two_way(rng), "y", ["A", "B"]).table for _ in range(n)]
    p_gg = np.array([t["p_gg"].to_numpy() for t in tables])
    p_unc = np.array([t["p_unc"].to_numpy() for t in tables])
    lo, hi = _band(n)
    gg_rate = (p_gg < 0.05).mean(axis=0)
    assert np.all(gg_rate >= lo) and np.all(gg_rate <= hi), gg_rate
    # without the correction the A effect (random slope) is liberal: the correction matters here
    assert (p_unc[:, 0] < 0.05).mean() > gg_rate[0]


def test_rm_anova_power_at_the_paper_effects():
    rng = np.random.default_rng(5)
    hits = []
    for _ in range(40):
        cm = cell_means(simulate_ordinal(rng), "correct", ["mode", "separation_D"])
        t = rm_anova(cm, "correct", ["mode", "separation_D"]).table.set_index("effect")
        hits.append((t.loc["mode", "p_gg"] < 0.05, t.loc["mode * separation_D", "p_gg"] < 0.05))
    hits = np.array(hits)
    assert hits[:, 0].mean() >= 0.95  # large mode effect
    assert hits[:, 1].mean() <= 0.25  # tiny interaction (the paper found none)


def test_condition_interaction_type_i_and_power():
    rng = np.random.default_rng(8)
    same = {"enabled": (1.13, 0.166), "disabled": (1.13, 0.166)}
    n = 120  # benchmarks/bench_statistics_calibration.py runs 1,000
    p_null = []
    for _ in range(n):
        d = simulate_reach(rng, lines=same, subject_sd=0.0)
        d["reach_fraction"] = d["reach_m"] / d["arm_reach_m"]
        p_null.append(condition_interaction(d, "target_fraction", "reach_fraction", "rendering").joint_p)
    lo, hi = _band(n)
    assert lo <= np.mean(np.array(p_null) < 0.05) <= hi
    differ = {"enabled": (1.13, 0.26), "disabled": (1.13, 0.166)}  # intercept +0.094
    power = []
    for _ in range(20):
        d = simulate_reach(rng, lines=differ, subject_sd=0.0)
        d["reach_fraction"] = d["reach_m"] / d["arm_reach_m"]
        power.append(condition_interaction(d, "target_fraction", "reach_fraction", "rendering", "disabled").joint_p < 0.05)
    assert np.mean(power) >= 0.9


def test_linear_fit_recovers_line_and_ci_covers():
    rng = np.random.default_rng(4)
    cover = []
    for _ in range(100):
        x = np.repeat([1.0, 2.0, 3.0], 6)
        y = 0.38 + 0.11 * x + rng.normal(0, 0.05, x.size)
        f = linear_fit(pd.DataFrame({"x": x, "y": y}), "x", "y")
        cover.append(f.slope_ci_low <= 0.11 <= f.slope_ci_high)
    lo, hi = _band(100, 0.95)
    assert lo <= np.mean(cover) <= min(hi, 1.0)


def test_binomial_one_tailed_size_is_exactly_at_most_alpha():
    """The exact size of the one-tailed test at n = 285 trials (19 subjects x 15), by enumeration."""
    from psyop.statistics.binomial import binomial_test

    n = 285
    rejecting = [k for k in range(n + 1) if binomial_test(k, n)["p"] < 0.05]
    size = binom.pmf(rejecting, n, 0.5).sum()
    assert 0.035 <= size <= 0.05
    assert rejecting == list(range(rejecting[0], n + 1))  # one-tailed: only the upper tail rejects


def test_binomial_preferences_null_and_effect():
    rng = np.random.default_rng(9)
    p_null = {("ocular", "conventional"): 0.5, ("reversed", "conventional"): 0.5, ("ocular", "reversed"): 0.5}
    n = 30  # the exact size is enumerated above; this checks the table plumbing under the null
    rej = []
    for _ in range(n):
        res = pairwise_preferences(simulate_realism(rng, n_subjects=19, p_first=p_null), pairs=list(p_null))
        rej.append((res["p"] < 0.05).to_numpy())
    _, hi = _band(n)
    assert np.all(np.mean(rej, axis=0) <= hi)
    res = pairwise_preferences(simulate_realism(rng), pairs=[("ocular", "conventional"), ("ocular", "reversed")])
    assert res["p"].iloc[0] < 0.001
    assert abs(res["proportion"].iloc[1] - 0.491) < 0.1
