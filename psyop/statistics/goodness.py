"""Goodness of fit of a binomial model: deviance and its parametric-bootstrap p-value.

psignifit's Python port dropped the deviance test of the MATLAB original. As there, the
simulated datasets are drawn from the fitted curve and compared with the *same* fitted
curve (no refit), so the test is cheap and vectorised: p = share of simulated deviances
>= the observed one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import xlogy


@dataclass(frozen=True)
class DevianceTest:
    deviance: float
    p_value: float
    n_bootstrap: int


def binomial_deviance(k: np.ndarray, n: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Deviance of success counts ``k`` of ``n`` against probabilities ``p`` (vs the saturated model).

    Broadcasts over leading axes of ``k`` (e.g. bootstrap samples x levels); sums the last axis.
    """
    k = np.asarray(k, float)
    n = np.asarray(n, float)
    p = np.clip(np.asarray(p, float), 1e-12, 1 - 1e-12)
    terms = xlogy(k, k / (n * p)) + xlogy(n - k, (n - k) / (n * (1 - p)))
    return 2.0 * terms.sum(axis=-1)


def deviance_test(k: np.ndarray, n: np.ndarray, p: np.ndarray, n_bootstrap: int = 2000, seed: int = 0) -> DevianceTest:
    """Observed deviance and the parametric-bootstrap p-value under the fitted ``p``."""
    k = np.asarray(k, float)
    n = np.asarray(n, int)
    p = np.asarray(p, float)
    observed = float(binomial_deviance(k, n, p))
    if n_bootstrap <= 0:
        return DevianceTest(observed, float("nan"), 0)
    rng = np.random.default_rng(seed)
    simulated = rng.binomial(n, p, size=(n_bootstrap, len(n)))
    sim_dev = binomial_deviance(simulated, n, p)
    p_value = float(np.mean(sim_dev >= observed - 1e-12))
    return DevianceTest(observed, p_value, n_bootstrap)
