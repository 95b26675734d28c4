"""psyop.statistics.signal_detection: d' and c against a hand computation, the log-linear correction, input
errors, and recovery of known d' and c from simulated equal-variance Gaussian observers."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from psyop.errors import UserError
from psyop.statistics.signal_detection import CORRECTION, rates, summary, t_summary

D_PRIME, CRITERION = 1.5, 0.2
N_SIGNAL = N_NOISE = 200
#: the mean d' (c) of 400 simulated participants lies within this of the true value (about 7 and 8 standard
#: errors of that mean, 0.007 and 0.004; the log-linear rule's own expected shift is -0.002 in d', -0.0003 in c)
D_TOLERANCE, C_TOLERANCE = 0.05, 0.03


def _table(counts: dict[tuple[str, str], tuple[int, int, int, int]]) -> pd.DataFrame:
    """Trials from (participant, mode) -> (hits, n_signal, false alarms, n_noise)."""
    rows = []
    for (p, mode), (h, ns, f, nn) in counts.items():
        rows += [(p, mode, True, i < h) for i in range(ns)] + [(p, mode, False, i < f) for i in range(nn)]
    return pd.DataFrame(rows, columns=["participant", "mode", "signal", "answer_yes"])


def _simulate(rng: np.random.Generator, d_prime: np.ndarray, criterion: np.ndarray,
              study: np.ndarray | None = None) -> pd.DataFrame:
    """One row per trial for equal-variance Gaussian observers: P(yes | signal) = Phi(d'/2 - c),
    P(yes | noise) = Phi(-d'/2 - c); one participant per entry of ``d_prime``."""
    n = N_SIGNAL + N_NOISE
    who = np.repeat(np.arange(len(d_prime)), n)
    signal = np.tile(np.r_[np.ones(N_SIGNAL, bool), np.zeros(N_NOISE, bool)], len(d_prime))
    p_yes = stats.norm.cdf(np.where(signal, 0.5, -0.5) * d_prime[who] - criterion[who])
    data = {"participant": who, "signal": signal, "answer_yes": rng.random(len(who)) < p_yes}
    if study is not None:
        data["study"] = study[who]
    return pd.DataFrame(data)


def test_d_prime_and_c_match_a_hand_computation_with_norm_ppf():
    t = _table({("p1", "ocular"): (14, 20, 5, 20), ("p1", "reversed"): (9, 12, 2, 15), ("p2", "ocular"): (7, 10, 4, 10)})
    r = rates(t, ["mode"]).set_index(["participant", "mode"])
    for key, (h, ns, f, nn) in {("p1", "ocular"): (14, 20, 5, 20), ("p1", "reversed"): (9, 12, 2, 15),
                                ("p2", "ocular"): (7, 10, 4, 10)}.items():
        zh, zf = stats.norm.ppf((h + 0.5) / (ns + 1)), stats.norm.ppf((f + 0.5) / (nn + 1))
        row = r.loc[key]
        assert (row["n_signal"], row["n_noise"], row["hits"], row["false_alarms"]) == (ns, nn, h, f)
        assert row["hit_rate"] == pytest.approx(h / ns) and row["fa_rate"] == pytest.approx(f / nn)
        assert row["d_prime"] == pytest.approx(zh - zf, rel=1e-12)
        assert row["criterion"] == pytest.approx(-(zh + zf) / 2, rel=1e-12)
        assert row["corrected"] and row["correction"] == CORRECTION and not row["extreme_rate"]


def test_rates_of_0_and_1_are_corrected_log_linearly_and_flagged():
    r = rates(_table({("p1", "x"): (10, 10, 0, 10)}), ["mode"]).iloc[0]
    assert r["hit_rate"] == 1.0 and r["fa_rate"] == 0.0 and r["extreme_rate"]
    assert r["hit_rate_corrected"] == pytest.approx(10.5 / 11) and r["fa_rate_corrected"] == pytest.approx(0.5 / 11)
    assert r["d_prime"] == pytest.approx(stats.norm.ppf(10.5 / 11) - stats.norm.ppf(0.5 / 11))
    assert np.isfinite(r["d_prime"]) and r["criterion"] == pytest.approx(0.0, abs=1e-12)


def test_no_conditions_and_0_1_columns_are_accepted():
    t = _table({("p1", "x"): (3, 4, 1, 4)})
    a = rates(t)
    b = rates(t.assign(signal=t["signal"].astype(int), answer_yes=t["answer_yes"].astype(float)))
    assert list(a.columns[:2]) == ["participant", "n_signal"]
    pd.testing.assert_frame_equal(a, b)


@pytest.mark.parametrize("drop, kind", [(True, "signal"), (False, "noise")])
def test_a_cell_without_signal_or_noise_trials_names_participant_and_condition(drop, kind):
    t = _table({("p1", "ocular"): (3, 4, 1, 4), ("p7", "reversed"): (3, 4, 1, 4)})
    t = t[~((t["participant"] == "p7") & (t["signal"] == drop))]
    with pytest.raises(UserError, match=rf"no {kind} trials for participant 'p7', mode='reversed'"):
        rates(t, ["mode"])


def test_bad_input_is_a_user_error_with_the_fix():
    t = _table({("p1", "x"): (3, 4, 1, 4)})
    with pytest.raises(UserError, match="missing value"):
        rates(t.assign(answer_yes=t["answer_yes"].astype(object).where(t.index > 0)))
    with pytest.raises(UserError, match="True/False"):
        rates(t.assign(answer_yes="yes"))
    with pytest.raises(UserError, match="'session'"):
        rates(t, ["session"])
    with pytest.raises(UserError, match="one row per participant"):
        summary(pd.concat([rates(t), rates(t)]))


def test_summary_t_interval_by_hand_and_flags_one_participant():
    t = pd.concat([_table({(p, "x"): (h, 20, f, 20)}) for p, h, f in
                   [("a", 15, 4), ("b", 12, 6), ("c", 17, 2), ("d", 20, 3)]])
    r = rates(t)
    s = summary(r).set_index("measure")
    d = r["d_prime"].to_numpy()
    half = stats.t.ppf(0.975, 3) * d.std(ddof=1) / 2
    assert s.loc["d_prime", "ci_low"] == pytest.approx(d.mean() - half)
    assert s.loc["d_prime", "ci_high"] == pytest.approx(d.mean() + half)
    assert s.loc["d_prime", "n"] == 4 and s.loc["d_prime", "n_extreme_rate"] == 1 and s.loc["d_prime", "flags"] == ""
    one = summary(rates(t[t["participant"] == "a"]), ci_level=0.9)
    assert (one["flags"] == "n_below_2").all() and one["ci_low"].isna().all() and one["sd"].isna().all()
    assert list(one["measure"]) == ["d_prime", "criterion"]


def test_t_summary_flags_zero_sd_and_non_finite_values():
    s = t_summary(pd.DataFrame({"g": ["a", "a", "b", "b", "b"], "x": [1.0, 1.0, 2.0, 3.0, np.inf]}), ["g"], ["x"])
    assert list(s["flags"]) == ["zero_sd", "excluded_nonfinite"]
    assert list(s["n"]) == [2, 2] and list(s["n_excluded"]) == [0, 1]
    with pytest.raises(UserError, match="ci_level"):
        t_summary(pd.DataFrame({"x": [1.0, 2.0]}), [], ["x"], ci_level=95)


def test_mean_estimate_recovers_d_prime_and_c():
    """400 simulated participants (seeded) with d' = 1.5, c = 0.2, 200 + 200 trials each."""
    rng = np.random.default_rng(20240611)
    n = 400
    r = rates(_simulate(rng, np.full(n, D_PRIME), np.full(n, CRITERION)))
    assert r["d_prime"].mean() == pytest.approx(D_PRIME, abs=D_TOLERANCE)
    assert r["criterion"].mean() == pytest.approx(CRITERION, abs=C_TOLERANCE)
    assert not r["extreme_rate"].any()


def test_ci_covers_the_population_d_prime_and_c_at_the_nominal_rate():
    """200 simulated studies of 12 participants whose d' ~ N(1.5, 0.3) and c ~ N(0.2, 0.2): the 95 % t intervals
    of the mean cover 1.5 and 0.2 at a rate a binomial test (p > 0.001) finds consistent with 95 %."""
    rng = np.random.default_rng(7)
    studies, per_study = 200, 12
    n = studies * per_study
    trials = _simulate(rng, rng.normal(D_PRIME, 0.3, n), rng.normal(CRITERION, 0.2, n),
                       study=np.repeat(np.arange(studies), per_study))
    s = summary(rates(trials, ["study"]), ["study"]).set_index("measure")
    for measure, truth in (("d_prime", D_PRIME), ("criterion", CRITERION)):
        rows = s.loc[measure]
        assert len(rows) == studies and (rows["n"] == per_study).all()
        covered = int(((rows["ci_low"] <= truth) & (truth <= rows["ci_high"])).sum())
        assert stats.binomtest(covered, studies, 0.95).pvalue > 0.001, (measure, covered)
