"""The second round of psyop.statistics.psychometric fast paths, held bit for bit to what they replaced
(kept here as ``_old_*``): the MAP zoom's ``np.linspace`` (:func:`modes._linspace`) and
``np.unique(np.append(...))`` (:func:`modes._with_point`), the log posterior's sparse ``meshgrid`` (reshaped
views), and psignifit's Configuration built once per grid / fixed parameters / CI level and never modified.
Each must give the same bits on many random inputs with edge values, and whole fits with the former
functions patched back in must equal today's field for field."""

from __future__ import annotations

import copy

import numpy as np
import psignifit
import pytest
from scipy import special

from psyop.statistics import posterior_modes as modes
from psyop.statistics import psignifit_grid as engine
from psyop.statistics import psignifit_posterior as model
from psyop.statistics.psychometric import FitOptions, GridSpec, fit_psychometric
from fit_equality import (
    LEVELS, fit_datasets, fit_grid, patch_everywhere, random_data, same_bits, same_fit, tabulated_priors,
)

pytestmark = pytest.mark.cross_cpu  # fast paths against the former code beside them, bit for bit



# ---- the former implementations -----------------------------------------------------------------------------------

def _old_shrink(grid, centre, bounds, points=15):
    out = {}
    for name, values in grid.items():
        values = np.atleast_1d(values)
        if len(values) < 2:
            out[name] = values
            continue
        step = (values[-1] - values[0]) / (len(values) - 1)
        lo = max(bounds[name][0], centre[name] - step)
        hi = min(bounds[name][1], centre[name] + step)
        out[name] = np.linspace(lo, hi, points)
    return out


def _old_refine_map(data, priors, local, grid_max):
    local = {n: np.unique(np.append(v, grid_max[n])) if len(np.atleast_1d(v)) > 1 else v for n, v in local.items()}
    return model._grid_argmax(local, _old_log_posterior_2afc(data, priors, local))[1]


def _old_log_posterior_2afc(data, priors, grid):
    names = sorted(grid)
    axes = [np.atleast_1d(np.asarray(grid[n], float)) for n in names]
    mesh = dict(zip(names, np.meshgrid(*axes, indexing="ij", sparse=True)))
    eta_std, gamma, lam, thr, width = (mesh[n] for n in ("eta", "gamma", "lambda", "threshold", "width"))
    x = data[:, 0].reshape((-1,) + (1,) * len(names))
    k, n = data[:, 1], data[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = x - thr
        z *= model._NORM_SPAN
        z = z / width
        special.ndtr(z, out=z)
        psi = (1.0 - gamma - lam) * z
        psi += gamma
        eta_var = eta_std ** 2
        beta = bool(np.any(eta_var > 1e-9))
        lp = model._binomial_log_likelihood(psi, k, n, overwrite=not beta)
        if beta:
            lp = model._beta_binomial_log_likelihood(psi, k, n, eta_var, lp)
        lp += np.log(priors["threshold"](thr))
        lp += np.log(priors["width"](width))
        lp += np.log(priors["lambda"](lam))
        lp += np.log(priors["gamma"](gamma))
        if beta or len(axes[0]) > 1:
            lp = lp + np.log(priors["eta"](eta_std))
    return np.broadcast_to(lp, tuple(len(v) for v in axes))


def _old_configuration(grid_spec, fixed, ci_level):
    return psignifit.Configuration(
        experiment_type="2AFC", sigmoid="norm", verbose=False, fixed_parameters=fixed,
        grid_steps=grid_spec.grid_steps(), steps_moving_bounds=grid_spec.sparse_steps(), confP=(ci_level,))




EDGES = [0.0, -0.0, 5e-324, -5e-324, 1e-310, 1e-300, 1e-16, 0.25, 0.5, 1.0, 1.0 + 2.2e-16, 3.0, 1e6, 1e300, -1e300]


def test_linspace_is_numpys():
    rng = np.random.default_rng(41)
    pairs = [(a, b) for a in EDGES for b in EDGES]
    pairs += [tuple(rng.uniform(-2, 3, 2)) for _ in range(500)]
    pairs += [(x, x + d) for x, d in zip(rng.uniform(-2, 2, 200), 10.0 ** rng.uniform(-320, 0, 200))]
    for lo, hi in pairs:
        for num in (2, 3, 9, 15, 16):
            assert same_bits(modes._linspace(lo, hi, num), np.linspace(lo, hi, num)), (lo, hi, num)
            assert same_bits(modes._linspace(np.float64(lo), np.float64(hi), num), np.linspace(lo, hi, num))


def test_with_point_is_unique_of_append():
    rng = np.random.default_rng(42)
    cases = []
    for _ in range(600):
        lo, hi = np.sort(rng.uniform(-1, 2, 2))
        values = np.linspace(lo, hi, int(rng.integers(2, 17)))
        point = float(rng.choice([rng.choice(values), rng.uniform(lo - 0.5, hi + 0.5), lo, hi, 0.0, -0.0]))
        cases.append((values, point))
    cases += [(np.array([-1.0, -0.0, 1.0]), 0.0), (np.array([-1.0, 0.0, 1.0]), -0.0), (np.array([0.0, 0.0]), 0.5),
              (np.array([1.0, 1.0, 1.0]), 1.0), (np.array([0.1, 0.2]), np.inf), (np.array([0.1, 0.2]), np.nan),
              (np.array([np.nan, 0.2]), 0.1), (np.array([0.2, 0.1]), 0.15), (np.array([5e-324, 1e-323]), 5e-324),
              (np.linspace(1.0, 1.0 + 1e-15, 15), 1.0 + 5e-16), (np.array([0.1, 0.2]), np.float64(0.2))]
    for values, point in cases:
        ours, numpys = modes._with_point(values, point), np.unique(np.append(values, point))
        assert same_bits(ours, numpys), (values, point)
        assert ours is not values








def test_log_posterior_views_are_the_meshgrid():
    rng = np.random.default_rng(43)
    for i in range(150):
        data = random_data(rng)
        priors = tabulated_priors(data)
        grid = fit_grid(rng, eta_free=i % 5 == 0)
        if i % 7 == 0:
            grid = {k: (float(v[0]) if i % 2 else list(v)) for k, v in grid.items()}  # scalars and lists
        new, old = model.log_posterior_2afc(data, priors, grid), _old_log_posterior_2afc(data, priors, grid)
        assert same_bits(new, old) and new.strides == old.strides


@pytest.mark.filterwarnings("ignore:invalid value encountered in subtract:RuntimeWarning")
def test_shrink_and_refine_map_bit_for_bit():
    rng = np.random.default_rng(44)
    for _ in range(100):
        data = random_data(rng)
        priors = tabulated_priors(data)
        grid = fit_grid(rng)
        best = {n: float(rng.choice(np.atleast_1d(v))) for n, v in grid.items()}
        bounds = {"eta": (0.0, 0.0), "gamma": (0.5, 0.5), "lambda": (0.0, 0.5), "threshold": (-0.5, 1.5),
                  "width": (0.01, 5.0)}
        new_box, old_box = modes._shrink(grid, best, bounds), _old_shrink(grid, best, bounds)
        assert list(new_box) == list(old_box) and all(same_bits(new_box[n], old_box[n]) for n in grid)
        assert modes._refine_map(data, priors, old_box, best) == _old_refine_map(data, priors, old_box, best)


def test_configuration_is_cached_and_never_modified():
    options = FitOptions(n_bootstrap=0, estimate_eta=False)
    data = np.c_[LEVELS, [3, 5, 9, 14, 15], np.full(5, 15)]
    fit_psychometric(data, options)
    conf = engine._configuration(options.grid, {"eta": 0.0}, options.ci_level)
    before = copy.deepcopy(vars(conf))
    fit_psychometric(data, options)
    fit_psychometric(np.c_[LEVELS, [8, 8, 9, 10, 15], np.full(5, 15)], options)
    assert engine._configuration(options.grid, {"eta": 0.0}, options.ci_level) is conf
    assert repr(vars(conf)) == repr(before)
    fresh = _old_configuration(options.grid, {"eta": 0.0}, options.ci_level)
    assert repr(vars(fresh)) == repr(vars(conf))
    assert engine._configuration(GridSpec().scaled(0.5), {"eta": 0.0}, 0.95) is not conf


OLD_FUNCTIONS = {"_shrink": _old_shrink, "_refine_map": _old_refine_map, "log_posterior_2afc": _old_log_posterior_2afc,
                 "_configuration": _old_configuration}






@pytest.mark.parametrize("options", [FitOptions(n_bootstrap=0, estimate_eta=False),
                                     FitOptions(grid=GridSpec().scaled(0.5), n_bootstrap=50),
                                     FitOptions(fixed_eta=None, n_bootstrap=0, estimate_eta=False),
                                     FitOptions(fixed_lambda=0.02, n_bootstrap=0, estimate_eta=False)],
                         ids=["power", "coarse-eta-estimated", "eta-free", "lambda-fixed"])
def test_fits_equal_the_former_functions(monkeypatch, options):
    datasets = fit_datasets(np.random.default_rng(45), 10)
    with np.errstate(invalid="ignore"):
        new = [fit_psychometric(d, options) for d in datasets]
        for name, old in OLD_FUNCTIONS.items():
            patch_everywhere(monkeypatch, name, old)
        old_fits = [fit_psychometric(d, options) for d in datasets]
    assert all(same_fit(a, b) for a, b in zip(new, old_fits))
