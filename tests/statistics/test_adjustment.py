"""psyop.statistics.adjustment: PSE, bias and SD by hand, flags, the RM-ANOVA of the PSE, and recovery of a
simulated observer's bias and SD (final = reference + b + N(0, s)) within the t intervals."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from psyop.errors import UserError
from psyop.statistics import anova
from psyop.statistics.adjustment import c4, pse_by_participant, summary

REFERENCE, BIAS, BIAS_SD, SD = 2.0, 0.3, 0.2, 0.5  # e.g. dioptres
TRIALS = 10


def _simulate(rng: np.random.Generator, studies: int, participants: int, bias: dict[str, float]) -> pd.DataFrame:
    """final = reference + b_p,condition + N(0, SD), b_p,condition ~ N(bias[condition], BIAS_SD)."""
    conds = np.array(list(bias))
    study, person, cond, _ = (a.ravel() for a in np.indices((studies, participants, len(conds), TRIALS)))
    b = rng.normal(np.array(list(bias.values())), BIAS_SD, (studies, participants, len(conds)))[study, person, cond]
    return pd.DataFrame({"study": study, "participant": person, "cond": conds[cond], "reference_value": REFERENCE,
                         "final_value": REFERENCE + b + rng.normal(0.0, SD, len(study))})


def _covered(rows: pd.DataFrame, truth: float) -> int:
    return int(((rows["ci_low"] <= truth) & (truth <= rows["ci_high"])).sum())


def test_pse_bias_and_sd_by_hand():
    t = pd.DataFrame({"participant": ["p1"] * 3 + ["p2"], "cond": "x", "final_value": [1.0, 1.5, 2.5, 4.0],
                      "reference_value": [1.0, 1.0, 1.0, 3.0]})
    r = pse_by_participant(t, ["cond"]).set_index("participant")
    assert r.loc["p1", "n"] == 3 and r.loc["p1", "pse"] == pytest.approx(5.0 / 3)
    assert r.loc["p1", "bias"] == pytest.approx(2.0 / 3) and r.loc["p1", "reference"] == 1.0
    assert r.loc["p1", "sd"] == pytest.approx(np.std([1.0, 1.5, 2.5], ddof=1)) and r.loc["p1", "flags"] == ""
    assert np.isnan(r.loc["p2", "sd"]) and r.loc["p2", "flags"] == "n_below_2" and r.loc["p2", "bias"] == 1.0


def test_a_changing_reference_is_flagged_and_sd_is_of_the_errors():
    t = pd.DataFrame({"participant": "p1", "final_value": [1.1, 2.1, 2.9], "reference_value": [1.0, 2.0, 3.0]})
    r = pse_by_participant(t).iloc[0]
    assert r["flags"] == "reference_varies" and r["reference"] == pytest.approx(2.0)
    assert r["bias"] == pytest.approx(1.0 / 30) and r["sd"] == pytest.approx(np.std([0.1, 0.1, -0.1], ddof=1))


def test_missing_values_name_the_participant_and_condition():
    t = pd.DataFrame({"participant": ["p1", "p9"], "cond": ["x", "near"], "final_value": [1.0, np.nan],
                      "reference_value": 1.0})
    with pytest.raises(UserError, match=r"'final_value'.*participant 'p9', cond='near'"):
        pse_by_participant(t, ["cond"])
    with pytest.raises(UserError, match="'reference_value'"):
        pse_by_participant(t.drop(columns="reference_value"), ["cond"])


def test_pse_bias_and_sd_are_recovered_within_their_cis():
    """200 simulated studies of 12 participants x 10 trials: the 95 % t intervals of the mean PSE, bias and SD cover
    reference + b, b and c4(10) * s (the SD's expectation) at rates consistent with 95 % (binomial p > 0.001)."""
    rng = np.random.default_rng(5)
    studies = 200
    pse = pse_by_participant(_simulate(rng, studies, 12, {"x": BIAS}), ["study"])
    result = summary(pse, ["study"], with_anova=False)
    assert result.anova is None and "with_anova=False" in result.anova_note
    table = result.table.set_index("measure")
    for measure, truth in (("pse", REFERENCE + BIAS), ("bias", BIAS), ("sd", c4(TRIALS) * SD)):
        rows = table.loc[measure]
        assert len(rows) == studies and (rows["flags"] == "").all()
        covered = _covered(rows, truth)
        assert stats.binomtest(covered, studies, 0.95).pvalue > 0.001, (measure, covered)
    assert (pse["sd"] / c4(TRIALS)).mean() == pytest.approx(SD, abs=0.01)  # about 4 standard errors of that mean
    assert pse["bias"].mean() == pytest.approx(BIAS, abs=0.02)


def test_summary_runs_the_rm_anova_of_the_pse_over_conditions():
    rng = np.random.default_rng(1)
    pse = pse_by_participant(_simulate(rng, 1, 10, {"near": 0.0, "far": 0.6}), ["study", "cond"])
    result = summary(pse, ["study", "cond"])  # 'study' has one level: left out of the ANOVA
    direct = anova.rm_anova(pse.drop(columns="study"), "pse", ["cond"])
    pd.testing.assert_frame_equal(result.anova.table, direct.table)
    assert result.anova.effect("cond")["p_gg"] < 0.001 and result.anova_note == ""
    assert list(result.table["measure"]) == ["pse", "bias", "sd"] * 2
    one = summary(pse[pse["cond"] == "far"], ["cond"])
    assert one.anova is None and "2 or more levels" in one.anova_note


def test_an_anova_that_cannot_run_says_why():
    rng = np.random.default_rng(2)
    pse = pse_by_participant(_simulate(rng, 1, 1, {"near": 0.0, "far": 0.6}), ["cond"])
    result = summary(pse, ["cond"])
    assert result.anova is None and "complete subject" in result.anova_note
    assert (result.table["flags"] == "n_below_2").all()
    with pytest.raises(UserError, match="one row per participant"):
        summary(pd.concat([pse, pse]), ["cond"])


def test_c4():
    rng = np.random.default_rng(0)
    assert c4(5) == pytest.approx(rng.normal(size=(200000, 5)).std(axis=1, ddof=1).mean(), abs=0.003)
