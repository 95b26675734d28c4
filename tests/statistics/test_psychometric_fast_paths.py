"""psyop.statistics.psychometric's fast paths, held bit for bit to the definitions they replaced.

The former implementations are kept here verbatim (``_old_*``): the 75 %-correct level and the
predicted proportion correct through psignifit's own 'norm' sigmoid (``scipy.stats.norm``), the
log posterior and posterior grid with NumPy temporaries, the MAP zoom through the normalised
posterior, the local maxima by ``maximum_filter`` over every axis, and ``np.isclose`` / ``np.allclose`` /
psignifit's ``parameter_grid`` for the grid checks. Each new path must give
the same bits (``tobytes``) on many random grids, levels and parameters, edge values included
(lapse 0 and 0.5, tiny and zero widths, extreme levels), and whole fits with the old functions
patched back in must equal today's fits field for field.
"""

from __future__ import annotations

import math

import numpy as np
import psignifit
import pytest
from scipy import ndimage, special
from scipy.stats import norm

from psyop.statistics import posterior_modes as modes
from psyop.statistics import psignifit_grid as engine
from psyop.statistics import psignifit_posterior as model
from psyop.statistics import psignifit_private as private
from psyop.statistics import psychometric as psy
from psyop.statistics.psychometric import FitOptions, GridSpec, fit_psychometric
from fit_equality import (
    LEVELS, fit_datasets, fit_grid, patch_everywhere, random_data, same_bits, same_fit, tabulated_priors,
)

parameter_grid = private.private_symbol("parameter_grid")  # psignifit's own, the reference of engine._parameter_grid

pytestmark = pytest.mark.cross_cpu  # fast paths against the former code beside them, bit for bit

SIGMOID = psignifit.sigmoids.sigmoid_by_name("norm", PC=0.5, alpha=0.05)


# ---- the former implementations (psyop before the fast paths) --------------------------------------------------

def _old_predicted_pc(level_D, location_D, width_D, lapse):
    sigmoid = psignifit.sigmoids.sigmoid_by_name("norm", PC=0.5, alpha=0.05)
    return np.asarray(sigmoid(level_D, location_D, width_D, psy.GUESS_2AFC, lapse), float)


def _old_t75_mesh(grid, sigmoid):
    names = sorted(grid)
    mesh = dict(zip(names, np.meshgrid(*[np.atleast_1d(grid[n]) for n in names], indexing="ij")))
    gamma = mesh["gamma"]
    with np.errstate(invalid="ignore", divide="ignore"):
        scaled = (psy.TARGET_PC - gamma) / (1.0 - mesh["lambda"] - gamma)
        t75 = sigmoid._inverse(np.clip(scaled, 0.0, 1.0), mesh["threshold"], mesh["width"])
    reachable = (scaled > 0.0) & (scaled < 1.0)
    t75 = np.where(reachable & np.isfinite(t75), t75, np.inf)
    return mesh, t75, names


def _old_t75(params):
    scaled = (psy.TARGET_PC - params["gamma"]) / (1.0 - params["lambda"] - params["gamma"])
    if not 0.0 < scaled < 1.0:
        return float("inf")
    return float(params["threshold"] + norm.ppf(scaled) * params["width"] / psy.WIDTH_PER_SIGMA)


def _old_log_posterior_2afc(data, priors, grid):
    names = sorted(grid)
    axes = [np.atleast_1d(np.asarray(grid[n], float)) for n in names]
    mesh = dict(zip(names, np.meshgrid(*axes, indexing="ij", sparse=True)))
    eta_std, gamma, lam, thr, width = (mesh[n] for n in ("eta", "gamma", "lambda", "threshold", "width"))
    x = data[:, 0].reshape((-1,) + (1,) * len(names))
    k = data[:, 1].reshape(x.shape)
    n = data[:, 2].reshape(x.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        psi = gamma + (1.0 - gamma - lam) * special.ndtr((x - thr) * model._NORM_SPAN / width)
        log_psi = np.where(k > 0, k * np.log(psi), 0.0)
        log_1m = np.where(n - k > 0, (n - k) * np.log(1.0 - psi), 0.0)
        eta_var = eta_std ** 2
        binomial = (log_psi + log_1m).sum(axis=0)
        if np.any(eta_var > 1e-9):
            eta_prime = np.where(eta_var > 1e-9, 1.0 / np.where(eta_var > 1e-9, eta_var, 1.0) - 1.0, 1.0)
            a, b = psi * eta_prime, (1.0 - psi) * eta_prime
            beta_bin = np.where(k > 0, special.gammaln(k + a) - special.gammaln(a), 0.0) \
                + np.where(n - k > 0, special.gammaln(n - k + b) - special.gammaln(b), 0.0) \
                - special.gammaln(n + eta_prime) + special.gammaln(eta_prime)
            lp = np.where(eta_var > 1e-9, beta_bin.sum(axis=0), binomial)
        else:
            lp = binomial
        lp = lp + np.log(priors["threshold"](thr)) + np.log(priors["width"](width)) \
            + np.log(priors["lambda"](lam)) + np.log(priors["gamma"](gamma))
        if np.any(eta_var > 1e-9) or len(axes[0]) > 1:
            lp = lp + np.log(priors["eta"](eta_std))
    return np.broadcast_to(lp, tuple(len(v) for v in axes))


def _old_posterior_2afc(data, priors, grid, log_posterior=None):
    lp = log_posterior if log_posterior is not None else _old_log_posterior_2afc(data, priors, grid)
    imax = np.unravel_index(int(np.argmax(lp)), lp.shape)
    names = sorted(grid)
    grid_max = {n: float(np.atleast_1d(grid[n])[i]) for n, i in zip(names, imax)}
    p = np.exp(lp - lp[imax]) * private.integral_weights([np.atleast_1d(grid[n]) for n in names])
    return p / p.sum(), grid_max


def _old_refine_map(data, priors, local, grid_max):
    local = {n: np.unique(np.append(v, grid_max[n])) if len(np.atleast_1d(v)) > 1 else v for n, v in local.items()}
    _, best = _old_posterior_2afc(data, priors, local)
    return best


def _old_local_maxima(values):
    return values == ndimage.maximum_filter(values, size=3, mode="nearest")


# ---- helpers ----------------------------------------------------------------------------------------------------



def _widths(rng, n):
    """Positive widths from subnormal to huge, with the edge values a grid can hold."""
    special_values = [5e-324, 1e-310, 1e-300, 1e-12, 1e-6, 0.25, 1.0, 1e6, 1e300]
    return np.sort(np.r_[rng.choice(special_values, 2), 10.0 ** rng.uniform(-8, 3, max(n - 2, 0))])[:n]


def _random_grid(rng, eta_free=False):
    n_lambda, n_thr, n_width = (int(v) for v in rng.integers(1, 8, 3))
    lambdas = [np.linspace(0.0, 0.5, n_lambda), np.sort(rng.uniform(0.0, 0.5, n_lambda)),
               np.array([0.0]), np.array([0.25]), np.array([0.5]), np.array([0.0, 0.25, 0.5])]
    thresholds = [rng.uniform(-2, 3, n_thr), rng.uniform(-1e6, 1e6, n_thr), np.zeros(1), np.array([-0.0])]
    lam = lambdas[int(rng.integers(len(lambdas)))]
    thr = np.sort(thresholds[int(rng.integers(len(thresholds)))])
    eta = np.sort(rng.uniform(0.0, 0.9, int(rng.integers(2, 5)))) if eta_free else np.array([0.0])
    gamma = np.array([0.5]) if rng.random() < 0.8 else np.array([rng.uniform(0.0, 0.6)])
    return {"eta": eta, "gamma": gamma, "lambda": np.asarray(lam, float), "threshold": np.asarray(thr, float),
            "width": _widths(rng, n_width)}








# ---- the 75 %-correct level and the predicted proportion correct -----------------------------------------------

def test_t75_mesh_is_psignifits_inverse_bit_for_bit():
    rng = np.random.default_rng(30)
    for _ in range(400):
        grid = _random_grid(rng, eta_free=rng.random() < 0.2)
        old_mesh, old_t75, old_names = _old_t75_mesh(grid, SIGMOID)
        mesh, t75, names = model._t75_mesh(grid)
        assert names == old_names
        assert same_bits(t75, old_t75), grid
        assert same_bits(model._t75_grid(grid), old_t75)
        assert all(same_bits(mesh[n], old_mesh[n]) for n in names)


def test_t75_is_norm_ppf_bit_for_bit():
    rng = np.random.default_rng(31)
    lapses = np.r_[0.0, 0.25, 0.2499999999, 0.49, 1e-300, rng.uniform(0.0, 0.5, 200)]
    for lapse in lapses:
        for gamma in (0.5, 0.0, float(rng.uniform(0.0, 0.7))):
            if 1.0 - lapse - gamma == 0.0:
                continue  # the former code raised ZeroDivisionError there (test_t75_flat_curve_is_inf)
            for thr, width in ((rng.uniform(-2, 3), _widths(rng, 1)[0]), (0.0, 1e-300), (-0.0, 5e-324),
                               (1e6, 1e6), (rng.uniform(-1, 1), 0.0)):
                p = {"gamma": gamma, "lambda": float(lapse), "threshold": float(thr), "width": float(width)}
                new, old = model._t75(p), _old_t75(p)
                assert type(new) is type(old) and (new == old or math.isnan(new) and math.isnan(old)), p
                assert math.copysign(1.0, new) == math.copysign(1.0, old), p


def test_t75_flat_curve_is_inf():
    """Lapse 0.5 at guess 0.5: the curve is flat at 50 % and never reaches 75 % (the former code raised
    ZeroDivisionError); a fit whose MAP lapse is 0.5 reports no threshold (status lapse_at_bound)."""
    assert model._t75({"gamma": 0.5, "lambda": 0.5, "threshold": 0.3, "width": 0.4}) == math.inf
    data = np.c_[LEVELS, [8, 7, 9, 8, 7], np.full(5, 15)]
    with pytest.warns(UserWarning, match="lapse rate"), np.errstate(invalid="ignore"):
        fit = fit_psychometric(data, FitOptions(fixed_lambda=0.5, n_bootstrap=0, estimate_eta=False))
    assert fit.lapse == 0.5
    assert fit.status == "lapse_at_bound"
    assert math.isnan(fit.threshold_D) and fit.threshold_bound_D == LEVELS.max()


def test_predicted_pc_is_psignifits_sigmoid_bit_for_bit():
    rng = np.random.default_rng(32)
    extreme = np.array([-1e308, -1e6, -0.0, 0.0, 1e-300, 1e6, 1e308, np.inf, -np.inf, np.nan])
    for _ in range(300):
        levels = np.r_[rng.uniform(-3, 4, int(rng.integers(1, 12))), rng.choice(extreme, 3)]
        location = float(rng.choice([rng.uniform(-2, 3), 0.0, -0.0, 1e6, -1e300]))
        width = float(rng.choice([_widths(rng, 1)[0], 0.0, -0.5, np.inf, np.nan]))
        lapse = float(rng.choice([0.0, 0.5, 1e-300, rng.uniform(0.0, 0.5)]))
        with np.errstate(over="ignore"):
            as_float32 = levels.astype(np.float32)  # 1e308 -> inf
        for lv in (levels, as_float32, levels[:1].reshape(()), float(levels[0])):
            with np.errstate(invalid="ignore", over="ignore"):  # extreme levels over tiny widths
                assert same_bits(psy.predicted_pc(lv, location, width, lapse),
                                  _old_predicted_pc(lv, location, width, lapse)), (lv, location, width, lapse)
    widths = _widths(rng, 5)
    with np.errstate(invalid="ignore"):  # a subnormal width's scale is 0
            assert same_bits(psy.predicted_pc(LEVELS[:, None], 0.3, widths, 0.02),
                              _old_predicted_pc(LEVELS[:, None], 0.3, widths, 0.02))


# ---- the posterior -------------------------------------------------------------------------------------------------

@pytest.mark.filterwarnings("ignore:invalid value encountered in subtract:RuntimeWarning")  # grids of prior 0 only
def test_log_posterior_and_posterior_bit_for_bit():
    rng = np.random.default_rng(33)
    for i in range(150):
        data = random_data(rng)
        priors = tabulated_priors(data)
        grid = fit_grid(rng, eta_free=i % 5 == 0)
        assert same_bits(model.log_posterior_2afc(data, priors, grid), _old_log_posterior_2afc(data, priors, grid))
        post, best = model.posterior_2afc(data, priors, grid)
        old_post, old_best = _old_posterior_2afc(data, priors, grid)
        assert same_bits(post, old_post) and best == old_best
        lp = _old_log_posterior_2afc(data, priors, grid)
        post, best = model.posterior_2afc(data, priors, grid, lp)
        assert same_bits(post, _old_posterior_2afc(data, priors, grid, lp)[0]) and best == old_best


@pytest.mark.filterwarnings("ignore:invalid value encountered in subtract:RuntimeWarning")
def test_refine_map_bit_for_bit():
    rng = np.random.default_rng(34)
    for _ in range(100):
        data = random_data(rng)
        priors = tabulated_priors(data)
        grid = fit_grid(rng)
        best = {n: float(rng.choice(np.atleast_1d(v))) for n, v in grid.items()}
        assert modes._refine_map(data, priors, grid, best) == _old_refine_map(data, priors, grid, best)


def test_local_maxima_is_maximum_filter():
    rng = np.random.default_rng(35)
    for _ in range(300):
        shape = tuple(int(rng.choice([1, 1, 2, 3, 7])) for _ in range(int(rng.integers(1, 6))))
        values = rng.integers(0, 4, shape).astype(float)  # many ties
        if rng.random() < 0.3:
            values[rng.random(shape) < 0.2] = -np.inf
        assert same_bits(modes._local_maxima(values), _old_local_maxima(values)), shape


# ---- closeness checks and psignifit's parameter grid --------------------------------------------------------------

def _close_pairs(rng):
    """Scalar pairs around numpy's tolerance edges, with zeros, infinities and NaN."""
    edge = [0.0, -0.0, 1e-8, -1e-8, 5e-324, 1.0, -1.0, 1e300, np.inf, -np.inf, np.nan, 0.5, 0.25]
    pairs = [(a, b) for a in edge for b in edge]
    for _ in range(3000):
        b = float(rng.choice([rng.uniform(-2, 2), 10.0 ** rng.uniform(-12, 12), 0.0]))
        tol = 1e-8 + 1e-5 * abs(b)
        a = b + float(rng.choice([-1, 1])) * tol * float(rng.choice([rng.uniform(0.0, 2.0), 1.0, np.nextafter(1.0, 2.0)]))
        pairs.append((a, b))
        pairs.append((np.float64(a), b))
    pairs += [(1, 1), (0, 1e-9), (3, 3.00001)]
    return pairs


def test_isclose_and_allclose_are_numpys():
    rng = np.random.default_rng(37)
    pairs = _close_pairs(rng)
    with np.errstate(invalid="ignore"):
        for a, b in pairs:
            assert engine._isclose(a, b) == bool(np.isclose(a, b)), (a, b)
    values = np.array([b for _, b in pairs], float)
    others = np.array([a for a, _ in pairs], float)
    for _ in range(2000):
        i = rng.integers(0, len(values), int(rng.integers(1, 6)))
        a, b = others[i], values[i]
        assert engine._allclose(a, b) == bool(np.allclose(a, b)), (a, b)
        assert engine._allclose(b, b) == bool(np.allclose(b, b))
        assert engine._allclose(a[:1], b) == bool(np.allclose(a[:1], b))


def test_parameter_grid_is_psignifits():
    rng = np.random.default_rng(38)
    for _ in range(500):
        bounds = {}
        for name in ("threshold", "width", "lambda", "gamma", "eta"):
            lo = float(rng.uniform(-1, 1))
            hi = float(rng.choice([lo, lo + 1e-9, lo + 1e-5 * abs(lo), lo + rng.uniform(0, 2), np.nextafter(lo, 2.0)]))
            bounds[name] = (lo, hi)
        steps = {n: int(rng.integers(1, 40)) for n in bounds}
        ours, theirs = engine._parameter_grid(bounds, steps), parameter_grid(bounds, steps)
        assert list(ours) == list(theirs)
        assert all(same_bits(ours[n], theirs[n]) for n in bounds)


# ---- whole fits with the former functions patched back in ---------------------------------------------------------

OLD_FUNCTIONS = {
    "predicted_pc": _old_predicted_pc, "_t75": _old_t75, "log_posterior_2afc": _old_log_posterior_2afc,
    "posterior_2afc": _old_posterior_2afc, "_refine_map": _old_refine_map, "_local_maxima": _old_local_maxima,
    "_t75_mesh": lambda grid: _old_t75_mesh(grid, SIGMOID), "_t75_grid": lambda grid: _old_t75_mesh(grid, SIGMOID)[1],
    "_isclose": np.isclose, "_allclose": np.allclose, "_parameter_grid": parameter_grid,
}






@pytest.mark.parametrize("options", [FitOptions(n_bootstrap=0, estimate_eta=False),
                                     FitOptions(grid=GridSpec().scaled(0.5), n_bootstrap=50),
                                     FitOptions(fixed_eta=None, n_bootstrap=0, estimate_eta=False)],
                         ids=["power", "coarse-eta-estimated", "eta-free"])
def test_fits_equal_the_former_functions(monkeypatch, options):
    datasets = fit_datasets(np.random.default_rng(36), 8)
    with np.errstate(invalid="ignore"):
        new = [fit_psychometric(d, options) for d in datasets]
        for name, old in OLD_FUNCTIONS.items():
            patch_everywhere(monkeypatch, name, old)
        old_fits = [fit_psychometric(d, options) for d in datasets]
    assert all(same_fit(a, b) for a, b in zip(new, old_fits))
