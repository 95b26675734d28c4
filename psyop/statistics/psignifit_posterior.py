"""psignifit's model for its 'norm' sigmoid, vectorised: the curve's parameters, the log posterior and
the posterior mass on a grid, the priors tabulated, and the level where a curve reaches a proportion.

Each function runs psignifit 4.3's operations in the same order, without ``scipy.stats``' per-call
overhead (tests/statistics/test_psychometric_fast_paths.py holds them to the former code bit for bit,
``test_log_posterior_matches_psignifit`` to psignifit's own log posterior). Grid axes are in
alphabetical order (eta, gamma, lambda, threshold, width), as psignifit orders its posterior.
"""

from __future__ import annotations

import numpy as np
from scipy import special
from scipy.stats import norm

from psyop.statistics.psignifit_private import integral_weights

#: The proportion correct a 2AFC threshold is read at.
TARGET_PC = 0.75
_NORM_SPAN = float(norm.ppf(0.95) - norm.ppf(0.05))  # psignifit 'norm' width: 5 %-95 % of the unscaled sigmoid
_PPF_HALF = float(special.ndtri(0.5))  # 0.0: psignifit's Gaussian loc is threshold - ndtri(PC=0.5) * scale
WIDTH_PER_SIGMA = 2.0 * float(norm.ppf(0.95))  # width (5 %-95 % of the cumulative normal) over its sigma, 3.2897...
# _NORM_SPAN is the same quantity written ppf(0.95) - ppf(0.05); it is 1 ulp larger than WIDTH_PER_SIGMA and
# kept as it is so the fits stay bit-identical.


def _norm_standard_parameters(threshold_D, width_D) -> tuple[np.ndarray, np.ndarray]:
    """psignifit's ``Gaussian(PC=0.5, alpha=0.05)._standard_parameters`` (sd ``scale`` and mean
    ``loc`` of the cumulative normal) with ``scipy.stats.norm.ppf`` written out: ``scale = width /
    (ppf(0.95) - ppf(0.05))``; ``loc = threshold - ppf(0.5, 0, scale)``, where ``ppf(0.5, 0, scale)``
    is ``ndtri(0.5) * scale + 0`` for scale > 0 and NaN otherwise (scipy's bad-argument value)."""
    scale = np.asarray(width_D, float) / _NORM_SPAN
    with np.errstate(invalid="ignore"):
        loc = threshold_D - np.where(scale > 0, _PPF_HALF * scale + 0, np.nan)
    return scale, np.asarray(loc)


def _t75_grid(grid: dict[str, np.ndarray], target: float | None = TARGET_PC) -> np.ndarray:
    """The 75 %-correct level (``target``: another proportion; None: the midpoint between the guess rate
    and ``1 - lambda``, the yes/no threshold) of every grid point (axes in alphabetical order), ``+inf``
    where the curve never reaches it (a flat or falling curve has no midpoint).

    psignifit's ``Gaussian._inverse`` is ``norm.ppf(q, loc, scale)``: ``ndtri(q) * scale + loc`` for
    0 < q < 1, scale > 0 and loc not NaN; with ``loc = threshold`` exactly there (``ndtri(0.5)`` is 0),
    the same operations run here, each on the axes it depends on (``q`` on gamma and lambda only),
    broadcast to the grid. Points psignifit's call left NaN or infinite are ``+inf`` as before.
    """
    names = sorted(grid)  # psignifit orders posterior axes alphabetically
    sparse = dict(zip(names, np.meshgrid(*[np.atleast_1d(grid[n]) for n in names], indexing="ij", sparse=True)))
    gamma, threshold, width = sparse["gamma"], sparse["threshold"], sparse["width"]
    with np.errstate(invalid="ignore", divide="ignore"):
        if target is None:
            scaled = np.where(1.0 - sparse["lambda"] - gamma > 0.0, 0.5, np.nan)
        else:
            scaled = (target - gamma) / (1.0 - sparse["lambda"] - gamma)
        scale, loc = _norm_standard_parameters(threshold, width)
        t75 = special.ndtri(np.clip(scaled, 0.0, 1.0)) * scale + loc
    valid = (scaled > 0.0) & (scaled < 1.0) & (scale > 0) & (loc == loc) & np.isfinite(t75)
    out = np.full(tuple(len(np.atleast_1d(grid[n])) for n in names), np.inf)
    np.copyto(out, t75, where=valid)
    return out


def _t75_mesh(grid: dict[str, np.ndarray], target: float | None = TARGET_PC
              ) -> tuple[dict[str, np.ndarray], np.ndarray, list[str]]:
    """The full meshgrid of ``grid`` (axes in alphabetical order), :func:`_t75_grid` and the axis names."""
    names = sorted(grid)
    mesh = dict(zip(names, np.meshgrid(*[np.atleast_1d(grid[n]) for n in names], indexing="ij")))
    return mesh, _t75_grid(grid, target), names


def _target_kwargs(target: float | None) -> dict[str, float | None]:
    """The threshold-level keyword of :func:`_t75`, :func:`_t75_grid`, :func:`_t75_mesh`: none for the
    2AFC 75 % (the 2AFC path calls them with their former arguments, which the fast-path tests patch
    the former definitions into), ``{"target": target}`` otherwise."""
    return {} if target == TARGET_PC else {"target": target}


def _t75(params: dict[str, float], target: float | None = TARGET_PC) -> float:
    """Level where the curve of ``params`` reaches 75 % correct (``target``: another proportion; None:
    its midpoint between guess rate and ``1 - lambda``, the yes/no threshold; inf if it never does).

    ``norm.ppf(q)`` for 0 < q < 1 is ``ndtri(q) * 1 + 0`` in scipy; written out. A curve with
    ``1 - lambda - gamma == 0`` (lapse 0.5 on a 2AFC grid's edge) is flat at the guess rate and never
    reaches 75 %: inf (the fit's status is then ``lapse_at_bound``), not a ZeroDivisionError.
    """
    span = 1.0 - params["lambda"] - params["gamma"]
    if span == 0.0 or target is None and not span > 0.0:
        return float("inf")
    scaled = 0.5 if target is None else (target - params["gamma"]) / span
    if not 0.0 < scaled < 1.0:
        return float("inf")
    return float(params["threshold"] + (special.ndtri(scaled) + 0.0) * params["width"] / WIDTH_PER_SIGMA)


def _binomial_log_likelihood(psi: np.ndarray, k: np.ndarray, n: np.ndarray, overwrite: bool) -> np.ndarray:
    """``sum over levels of k log(psi) + (n - k) log(1 - psi)``, a term 0 where its count is 0
    (``psi`` has the levels on axis 0; ``k`` and ``n`` one count per level). The same operations as
    ``np.where(k > 0, k * np.log(psi), 0.0) + np.where(n - k > 0, (n - k) * np.log(1.0 - psi), 0.0)``
    summed over axis 0, in place: ``psi`` is overwritten when ``overwrite``."""
    shape = (-1,) + (1,) * (psi.ndim - 1)
    log_psi = np.log(psi)
    log_psi *= k.reshape(shape)
    log_psi[~(k > 0)] = 0.0
    log_1m = np.subtract(1.0, psi, out=psi if overwrite else None)
    np.log(log_1m, out=log_1m)
    log_1m *= (n - k).reshape(shape)
    log_1m[~(n - k > 0)] = 0.0
    log_psi += log_1m
    return log_psi.sum(axis=0)


def _beta_binomial_log_likelihood(psi: np.ndarray, k: np.ndarray, n: np.ndarray, eta_var: np.ndarray,
                                  binomial: np.ndarray) -> np.ndarray:
    """psignifit's beta-binomial log likelihood where ``eta_var > 1e-9`` (``binomial`` elsewhere)."""
    k = k.reshape((-1,) + (1,) * (psi.ndim - 1))
    n = n.reshape(k.shape)
    eta_prime = np.where(eta_var > 1e-9, 1.0 / np.where(eta_var > 1e-9, eta_var, 1.0) - 1.0, 1.0)
    a, b = psi * eta_prime, (1.0 - psi) * eta_prime
    beta_bin = np.where(k > 0, special.gammaln(k + a) - special.gammaln(a), 0.0) \
        + np.where(n - k > 0, special.gammaln(n - k + b) - special.gammaln(b), 0.0) \
        - special.gammaln(n + eta_prime) + special.gammaln(eta_prime)
    return np.where(eta_var > 1e-9, beta_bin.sum(axis=0), binomial)


def log_posterior_2afc(data: np.ndarray, priors, grid: dict[str, np.ndarray]) -> np.ndarray:
    """psignifit 4.3's ``log_posterior`` for the 2AFC 'norm' sigmoid, vectorised over levels.

    Same model, priors and axis order (alphabetical: eta, gamma, lambda, threshold, width);
    psignifit evaluates its sigmoid through scalar ``scipy.stats`` calls whose overhead
    (~9 ms a call) dominated psyop's fits. ``test_log_posterior_matches_psignifit`` checks equality.
    The arrays over levels x grid are computed in place (same operations, same order).
    """
    names = sorted(grid)
    axes = [np.atleast_1d(np.asarray(grid[n], float)) for n in names]
    # the sparse 'ij' meshgrid's arrays (each axis's values along its own dimension), as reshaped views
    eta_std, gamma, lam, thr, width = (v.reshape((1,) * i + (-1,) + (1,) * (len(axes) - i - 1))
                                       for i, v in enumerate(axes))
    x = data[:, 0].reshape((-1,) + (1,) * len(names))
    k, n = data[:, 1], data[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = x - thr
        z *= _NORM_SPAN
        z = z / width
        special.ndtr(z, out=z)
        psi = (1.0 - gamma - lam) * z
        psi += gamma
        eta_var = eta_std ** 2
        beta = bool(np.any(eta_var > 1e-9))
        lp = _binomial_log_likelihood(psi, k, n, overwrite=not beta)
        if beta:
            lp = _beta_binomial_log_likelihood(psi, k, n, eta_var, lp)
        lp += np.log(priors["threshold"](thr))
        lp += np.log(priors["width"](width))
        lp += np.log(priors["lambda"](lam))
        lp += np.log(priors["gamma"](gamma))
        if beta or len(axes[0]) > 1:
            lp = lp + np.log(priors["eta"](eta_std))
    return np.broadcast_to(lp, tuple(len(v) for v in axes))


def _grid_argmax(grid: dict[str, np.ndarray], lp: np.ndarray) -> tuple[tuple[int, ...], dict[str, float]]:
    """The index of the largest ``lp`` (first in C order) and the grid point there."""
    imax = tuple(int(i) for i in np.unravel_index(int(np.argmax(lp)), lp.shape))
    return imax, {n: float(np.atleast_1d(grid[n])[i]) for n, i in zip(sorted(grid), imax)}


def posterior_2afc(data: np.ndarray, priors, grid: dict[str, np.ndarray], log_posterior: np.ndarray | None = None
                   ) -> tuple[np.ndarray, dict[str, float]]:
    """psignifit's ``posterior_grid`` (normalised trapezoid mass per grid point, grid maximum)
    on :func:`log_posterior_2afc`."""
    lp = log_posterior if log_posterior is not None else log_posterior_2afc(data, priors, grid)
    imax, grid_max = _grid_argmax(grid, lp)
    p = lp - lp[imax]
    np.exp(p, out=p)
    p *= integral_weights([np.atleast_1d(grid[n]) for n in sorted(grid)])
    p /= p.sum()
    return p, grid_max


def tabulate_priors(priors, bounds: dict[str, tuple[float, float]], points: int = 20001) -> dict:
    """psignifit's normalised priors as lookup tables over their bounds (linear interpolation).

    psignifit's width prior freezes a ``scipy.stats`` distribution on every call (~1 ms);
    a fit evaluates priors some 15 times. Relative interpolation error < 1e-5 at 20001 points.
    """
    out = {}
    for name, prior in priors.items():
        lo, hi = bounds[name]
        if np.isclose(lo, hi):
            value = float(np.asarray(prior(np.array([lo], float)))[0])
            out[name] = (lambda v: lambda x: np.full(np.shape(x), v))(value)
            continue
        xs = np.linspace(lo, hi, points)
        ys = np.asarray(prior(xs), float)
        out[name] = (lambda xs_, ys_: lambda x: np.interp(x, xs_, ys_, left=0.0, right=0.0))(xs, ys)
    return out
