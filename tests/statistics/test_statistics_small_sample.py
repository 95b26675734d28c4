"""CR2 cluster-robust errors with Satterthwaite df and the HTZ Wald test against R's clubSandwich (goldens
made by tests/fixtures/r/clubsandwich_golden.R, R 4.2.2, clubSandwich 0.5.8; R is not needed to run this)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from psyop.statistics.regression import mixed_condition_comparison
from psyop.statistics.small_sample import MIN_RELIABLE_DF, cr2_test, cr2_vcov

pytestmark = pytest.mark.cross_cpu

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "r"


def _design(n: int):
    d = pd.read_csv(FIXTURES / f"design_cluster{n}.csv")
    x = np.column_stack([np.ones(len(d)), d["xc"], d["other"], d["xc"] * d["other"]])
    return d, x


@pytest.mark.parametrize("n", [3, 5, 12])
def test_cr2_satterthwaite_and_htz_match_clubsandwich(n):
    d, x = _design(n)
    y, cl = d["y"].to_numpy(), d["participant"].to_numpy()
    np.testing.assert_allclose(cr2_vcov(x, y, cl), pd.read_csv(FIXTURES / f"golden_cluster{n}_vcov.csv")
                               .set_index("term").to_numpy(), rtol=1e-9)
    golden = pd.read_csv(FIXTURES / f"golden_cluster{n}_coef.csv")
    for i, row in golden.iterrows():
        t = cr2_test(x, y, cl, np.eye(4)[i])
        np.testing.assert_allclose([t.estimate[0], t.se[0], t.statistic, t.df_denom, t.p],
                                   [row["estimate"], row["se"], row["t"], row["df"], row["p"]], rtol=1e-8)
    wald = pd.read_csv(FIXTURES / f"golden_cluster{n}_wald.csv").set_index("test")
    joint = cr2_test(x, y, cl, np.eye(4)[2:])
    np.testing.assert_allclose([joint.statistic, joint.df_denom, joint.p],
                               wald.loc["HTZ", ["Fstat", "df_denom", "p"]].astype(float), rtol=1e-8)
    np.testing.assert_allclose(joint.wald_q / 2, wald.loc["chi-sq", "Fstat"], rtol=1e-8)
    assert joint.low_df == (joint.df_denom < MIN_RELIABLE_DF)


def test_three_participants_fallback_is_cr2_htz_flagged_not_a_confident_chi2():
    """The issue's case: 3 participants, MixedLM fails, the fallback reported chi2(2) = 148.76, p < 0.0001 with
    CR1 errors over 3 clusters. Now: CR2, an HTZ F with its (tiny) df, flagged few participants and low df."""
    d, _ = _design(3)
    d = d.assign(rendering=np.where(d["other"] == 1, "enabled", "disabled"))
    m = mixed_condition_comparison(d, "x", "y", "rendering", reference="disabled")
    if m.method.startswith("OLS"):
        assert m.joint_test == "HTZ F" and m.joint_df_denom < MIN_RELIABLE_DF
        assert "low_df" in m.flags and "few_participants" in m.flags and "LOW DF" in m.flag_text
        assert "CR2" in m.method
    else:  # the mixed model fitted: flagged for its 3 participants
        assert "few_participants" in m.flags


def test_one_cluster_is_refused():
    d, x = _design(3)
    with pytest.raises(ValueError, match="at least 2 clusters"):
        cr2_test(x, d["y"], np.zeros(len(d)), np.eye(4)[3])


def _balanced_two_clusters(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two participants with the same design rows (egocentric's: target fractions x two renderings), y random."""
    xc = np.tile(np.repeat([-0.3, -0.1, 0.1, 0.3], 2), 2)
    other = np.tile([0.0, 1.0], 8)
    x = np.column_stack([np.ones(16), xc, other, xc * other])
    return x, rng.normal(size=16), np.repeat(["S01", "S02"], 8)


def test_two_balanced_clusters_refuse_two_contrasts_whatever_the_last_bits():
    """Two clusters of the same design cannot inform two contrasts: the CR2 scores sum to zero in exact arithmetic,
    so C V C' is singular and its smallest eigenvalue is rounding noise, of either sign by the CPU's kernels (an
    AVX-512 machine refused the joint test where an AVX2 one returned p = 0.99999999999999). Refused on every draw,
    with the last bits of x and y perturbed as another machine's kernels would perturb them."""
    from psyop.statistics.small_sample import SINGULAR_RATIO, _g_vectors

    rng = np.random.default_rng(39)
    joint = np.eye(4)[2:]
    for _ in range(200):
        x, y, cl = _balanced_two_clusters(rng)
        y = y * (1.0 + rng.uniform(-4, 4, size=y.shape) * np.finfo(float).eps)
        g, _ = _g_vectors(x, cl, joint)
        eigenvalues = np.linalg.eigvalsh((g @ y) @ (g @ y).T)
        assert abs(eigenvalues[0]) < 1e-6 * SINGULAR_RATIO * eigenvalues[-1]  # noise, far below the threshold
        with pytest.raises(ValueError, match="singular"):
            cr2_test(x, y, cl, joint)
        assert np.isfinite(cr2_test(x, y, cl, joint[1]).p)  # one contrast: informed, a number


def test_an_informed_contrast_pair_is_not_refused():
    """The threshold refuses only the singular case: two clusters of different designs inform both contrasts."""
    rng = np.random.default_rng(40)
    x, y, cl = _balanced_two_clusters(rng)
    x[8:, 1] = x[8:, 1] * 1.7 + 0.05  # S02's targets at other distances
    x[:, 3] = x[:, 1] * x[:, 2]
    assert np.isfinite(cr2_test(x, y, cl, np.eye(4)[2:]).wald_q)
