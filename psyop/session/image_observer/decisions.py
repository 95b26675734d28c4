"""The image observer's decision rules on its intervals' internal responses (contrast^2 deg^2), each response
perturbed by independent Gaussian internal noise of sd ``noise_sd``:

- n intervals (``n_afc``; ``two_interval`` is n = 2): it picks the interval whose noisy response is largest;
  :func:`p_largest` is each interval's probability of being picked,
  ``p_j = integral phi(x) prod_(k != j) Phi(x + (R_j - R_k) / noise_sd) dx`` (Gauss-Hermite quadrature,
  :data:`QUADRATURE_NODES` nodes). Intervals with the same response are picked equally often.
- one interval (``yes_no``): it says yes when the noisy response exceeds ``criterion_sd x noise_sd``:
  :func:`p_yes` is ``Phi(R / noise_sd - criterion_sd)``. A stimulus without relative motion (R = 0) gets the
  false-alarm rate ``Phi(-criterion_sd)``, signal or not.

A lapse (rate ``lapse``) answers by a guess among the alternatives, each equally likely.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import ndtr

#: nodes of the Gauss-Hermite quadrature of :func:`p_largest` (exact to about 1e-12 for these smooth integrands)
QUADRATURE_NODES = 64


def p_largest(responses: tuple[float, ...], noise_sd: float, lapse: float) -> np.ndarray:
    """Each interval's probability of being picked (see the module docstring); sums to 1."""
    r = np.asarray(responses, dtype=np.float64) / noise_sd
    nodes, weights = np.polynomial.hermite_e.hermegauss(QUADRATURE_NODES)  # weight exp(-x^2 / 2)
    weights = weights / math.sqrt(2.0 * math.pi)
    out = np.empty(len(r))
    for j in range(len(r)):
        others = np.delete(r, j)
        cdf = ndtr(nodes[:, None] + (r[j] - others)[None, :])
        out[j] = float(np.sum(weights * np.prod(cdf, axis=1)))
    out = out / np.sum(out)
    return lapse / len(r) + (1.0 - lapse) * out


def p_yes(response: float, noise_sd: float, criterion_sd: float, lapse: float) -> float:
    """p("yes") to one interval's response (see the module docstring)."""
    z = response / noise_sd - criterion_sd
    return 0.5 * lapse + (1.0 - lapse) * 0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))
