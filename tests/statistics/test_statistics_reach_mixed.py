"""Egocentric reach: the subject-aware primary test (MixedLM) beside the pooled regression."""

from __future__ import annotations

import numpy as np

from psyop.statistics.regression import condition_interaction, mixed_condition_comparison
from psyop.statistics.simulate import simulate_reach

SAME = {"enabled": (1.1345, 0.166), "disabled": (1.1345, 0.166)}


def _data(seed: int, **kw):
    d = simulate_reach(np.random.default_rng(seed), lines=kw.pop("lines", SAME), noise_sd=0.05 / 0.7,
                       subject_sd=0.03 / 0.7, slope_sd=0.10, max_reach_fraction=1.2, **kw)
    d["reach_fraction"] = d["reach_m"] / d["arm_reach_m"]
    return d


def test_mixed_model_is_the_primary_test_and_recovers_the_line():
    m = mixed_condition_comparison(_data(1), "target_fraction", "reach_fraction", "rendering", reference="disabled")
    assert m.method.startswith("MixedLM, random intercept and slope") and m.fallback_reason == ""
    # reaches are bounded at 1.2 x arm reach, which flattens the top of the line (slope ~1.0, not 1.13)
    assert 0.85 < m.slope < 1.2 and m.n_subjects == 13 and m.n == 780
    assert 0.0 <= m.joint_p <= 1.0 and m.joint_df == 2


def test_pooled_regression_is_reported_beside_the_mixed_model():

    independent; the mixed model's p and the pooled p are both reported (here they differ)."""
    d = _data(3)
    pooled = condition_interaction(d, "target_fraction", "reach_fraction", "rendering", "disabled")
    mixed = mixed_condition_comparison(d, "target_fraction", "reach_fraction", "rendering", reference="disabled")
    assert pooled.n == mixed.n == 780 and pooled.joint_p != mixed.joint_p


def test_fallback_states_its_reason():
    d = _data(2, n_subjects=2)
    m = mixed_condition_comparison(d, "target_fraction", "reach_fraction", "rendering")
    assert m.method.startswith("OLS") and "only 2 participant" in m.fallback_reason
    flat = _data(4)
    flat["reach_fraction"] = 0.2 + 1.1 * flat["target_fraction"] + np.random.default_rng(0).normal(0, 0.05, len(flat))
    m = mixed_condition_comparison(flat, "target_fraction", "reach_fraction", "rendering")
    assert not m.method.startswith("MixedLM, random intercept and slope")
    assert "singular" in m.fallback_reason


def test_null_rejection_rate_of_the_mixed_test_is_near_nominal():
    """30 null re-simulations (the bench runs 300): at most a few rejections at alpha 0.05."""
    rejections = sum(mixed_condition_comparison(_data(100 + i), "target_fraction", "reach_fraction", "rendering").joint_p < 0.05
                     for i in range(30))
    assert rejections <= 5
