"""The Tobit (censored-normal) fit against R's survival::survreg(dist = "gaussian") (goldens made by
tests/fixtures/r/survreg_golden.R, R 4.2.2, survival 3.5.3, from the designs of
tests/fixtures/r/make_tobit_inputs.py; R is not needed to run this).

Tolerance: 1e-10 relative on coefficients, standard errors and sigma, 1e-10 absolute on the
log-likelihood. Both fits stop at the maximum, not at the same iterate: R's Newton-Raphson ran to a
relative log-likelihood change of 1e-13, psyop's BFGS then Newton steps to a gradient under 1e-13,
and with the analytic observed information on both sides the agreement measured was 5e-16 (SE,
sigma, coefficients) and 1e-14 (log-likelihood). 1e-10 leaves room for another platform's rounding
but fails an optimiser that stops short: psyop's earlier BFGS-only fit with a finite-difference
Hessian differed from R by 1e-8 to 4e-8."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from psyop.statistics.censored import censored_condition_means, censored_line, tobit_mean

pytestmark = pytest.mark.cross_cpu  # recorded R values: the tolerance must hold on every CPU

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "r"
RTOL = 1e-10


def _fit(name: str):
    d = pd.read_csv(FIXTURES / f"design_tobit_{name}.csv")
    if name == "mean":
        return tobit_mean(d["y"].to_numpy(), d["side"].to_numpy())
    if name == "line":
        return censored_line(d, "x")
    return censored_condition_means(d, "cond")


@pytest.mark.parametrize("name", ["mean", "line", "cells"])
def test_tobit_equals_survreg(name):
    fit = _fit(name)
    golden = pd.read_csv(FIXTURES / f"golden_tobit_{name}_coef.csv")
    summary = pd.read_csv(FIXTURES / f"golden_tobit_{name}_fit.csv").iloc[0]
    coefs = golden[golden["term"] != "Log(scale)"]
    assert len(coefs) == len(fit.coef)
    np.testing.assert_allclose(fit.coef, coefs["estimate"], rtol=RTOL)
    np.testing.assert_allclose(fit.se, coefs["se"], rtol=RTOL)
    assert fit.sigma == pytest.approx(summary["scale"], rel=RTOL)
    assert fit.loglik == pytest.approx(summary["loglik"], abs=1e-10)
    assert (fit.n, fit.n_below, fit.n_above) == (summary["n"], summary["n_left"], summary["n_right"])
    assert fit.converged


def test_goldens_record_their_r_and_survival_versions():
    versions = json.loads((FIXTURES / "golden_survreg_versions.json").read_text())
    assert set(versions) == {"R", "survival"}
    for name in ("mean", "line", "cells"):
        sides = pd.read_csv(FIXTURES / f"design_tobit_{name}.csv")["side"]
        assert (sides < 0).any() and (sides > 0).any(), f"{name}: the golden design is censored on both sides"


def test_participant_clustered_sandwich_equals_survreg_robust_variance():
    """5 participants x 3 conditions, censored on both sides (design_tobit_clustered.csv): psyop's
    sandwich before its G / (G - 1) factor equals survreg(..., cluster = participant)'s robust
    variance (fit$var; measured 1.6e-15 relative); the reported SEs are it times sqrt(G / (G - 1)) and
    the intervals use t on G - 1 = 4 df."""
    d = pd.read_csv(FIXTURES / "design_tobit_clustered.csv")
    fit = censored_condition_means(d, "cond", clusters=d["participant"].to_numpy())
    golden = pd.read_csv(FIXTURES / "golden_tobit_clustered_coef.csv")
    summary = pd.read_csv(FIXTURES / "golden_tobit_clustered_fit.csv").iloc[0]
    np.testing.assert_allclose(fit.coef, golden["estimate"][:3], rtol=RTOL)
    np.testing.assert_allclose(fit.se_sandwich, golden["robust_se"], rtol=RTOL)
    np.testing.assert_allclose(fit.se, golden["robust_se"][:3] * np.sqrt(5 / 4), rtol=RTOL)
    assert fit.sigma == pytest.approx(summary["scale"], rel=RTOL)
    assert (fit.n_clusters, fit.df_interval, fit.low_df) == (5, 4, False)
    assert "participant-clustered SEs (5 participants, t on 4 df)" in fit.model
    sides = d["side"]
    assert (sides < 0).any() and (sides > 0).any()
