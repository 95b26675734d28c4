"""2AFC psychometric functions with psignifit 4.3 (cumulative normal on linear diopters).

Why not simply ``psignifit.psignifit``: its last step refines the MAP with a Nelder-Mead
search whose objective calls ``scipy.stats.norm.ppf`` on scalars; that step is ~75 % of a
~1-2 s fit here, while the grid posterior (priors, bounds, credible intervals) costs tens
of ms. psyop runs psignifit's own pipeline (its Configuration, parameter bounds, default
priors, sparse grid -> tightened bounds -> dense grid), replaces the Nelder-Mead step by
two vectorised zoom-in grids around the posterior mode, and reports:

- ``threshold_D``: the 75 %-correct level of the MAP curve (what ``res.threshold(0.75)``
  returns for psignifit's MAP; lapse included, so it is *not* the 'threshold' parameter);
- ``threshold_ci_*_D``: 2.5/97.5 % posterior percentiles of the 75 %-correct level computed
  at every grid point (``res.threshold``'s CIs combine corners of marginal CIs and are,
  per its docstring, "only upper bounds");
- width, lapse (MAP), eta (overdispersion; see :class:`FitOptions`), and a deviance test.

``tests/statistics/test_statistics_psychometric.py`` checks agreement with the public
``psignifit.psignifit`` and recovery/coverage on simulated observers.

Degenerate data is flagged (``flags``), never silently returned: ``fewer_than_two_levels``
(no fit), ``all_correct``, ``threshold_outside_range``, ``posterior_at_grid_edge``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field, replace

import numpy as np
import pandas as pd
import psignifit
from scipy.stats import norm
from psignifit._parameter import masked_parameter_bounds, parameter_bounds, parameter_grid
from psignifit._posterior import posterior_grid
from psignifit._priors import setup_priors

from psyop.statistics.goodness import deviance_test

#: Mass of a normalised marginal at the outermost grid point above which the posterior
#: is considered cut by the grid (psignifit's own sanity-check value).
EDGE_MASS = 1e-3
TARGET_PC = 0.75
GUESS_2AFC = 0.5


@dataclass(frozen=True)
class GridSpec:
    """psignifit grid resolution: dense steps per parameter and sparse (bound-finding) steps.

    psignifit 4.3's 2AFC defaults are dense threshold 40, width 40, lambda 20, eta 20 and
    sparse 30/40/10/20. ``DEFAULT`` is the knee measured by
    ``benchmarks/bench_statistics_psignifit_grid.py`` (see docs/statistics.md).
    """

    threshold: int = 25
    width: int = 20
    lambda_: int = 10
    eta: int = 8
    sparse_threshold: int = 15
    sparse_width: int = 15
    sparse_lambda: int = 6
    sparse_eta: int = 6

    def scaled(self, factor: float) -> GridSpec:
        """Every step count multiplied by ``factor`` (at least 3 each)."""
        return GridSpec(**{k: max(3, int(round(v * factor))) for k, v in asdict(self).items()})

    def grid_steps(self) -> dict[str, int]:
        return {"threshold": self.threshold, "width": self.width, "lambda": self.lambda_, "eta": self.eta}

    def sparse_steps(self) -> dict[str, int]:
        return {
            "threshold": self.sparse_threshold,
            "width": self.sparse_width,
            "lambda": self.sparse_lambda,
            "eta": self.sparse_eta,
        }

    @property
    def dense_points(self) -> int:
        return self.threshold * self.width * self.lambda_ * self.eta


PSIGNIFIT_DEFAULT_GRID = GridSpec(40, 40, 20, 20, 30, 40, 10, 20)


@dataclass(frozen=True)
class FitOptions:
    """Everything that changes a fit besides the data."""

    grid: GridSpec = field(default_factory=GridSpec)
    fixed_lambda: float | None = None
    #: eta (overdispersion) is fixed to 0 for the threshold and its interval: with free eta the
    #: 95 % intervals covered the true threshold in 100 % of simulated observers (too wide); with
    #: eta = 0 coverage is ~98 % (docs/statistics.md). Overdispersion is still estimated
    #: (``estimate_eta``) and tested by the deviance bootstrap.
    fixed_eta: float | None = 0.0
    estimate_eta: bool = True
    ci_level: float = 0.95
    n_bootstrap: int = 2000
    seed: int = 0
    map_refinements: int = 2


@dataclass(frozen=True)
class PsychometricFit:
    """One 2AFC psychometric fit. Levels in diopters; NaN where no fit was possible."""

    threshold_D: float
    threshold_ci_low_D: float
    threshold_ci_high_D: float
    width_D: float  # psignifit width: distance between the 5 % and 95 % points of the unscaled sigmoid
    sigma_D: float  # sd of the cumulative normal (width / 3.29)
    location_D: float  # psignifit 'threshold' parameter: 50 % point of the unscaled sigmoid
    lapse: float
    eta: float
    deviance: float
    deviance_p: float
    n_levels: int
    n_trials: int
    level_min_D: float
    level_max_D: float
    flags: tuple[str, ...]

    @property
    def ci_width_D(self) -> float:
        return self.threshold_ci_high_D - self.threshold_ci_low_D

    @property
    def ok(self) -> bool:
        return not self.flags

    def proportion_correct(self, level_D: np.ndarray) -> np.ndarray:
        """The fitted 2AFC curve (guess 0.5, fitted lapse) at ``level_D``."""
        return predicted_pc(np.asarray(level_D, float), self.location_D, self.width_D, self.lapse)


def predicted_pc(level_D: np.ndarray, location_D: float, width_D: float, lapse: float) -> np.ndarray:
    """2AFC proportion correct of psignifit's 'norm' sigmoid with guess rate 0.5."""
    sigmoid = psignifit.sigmoids.sigmoid_by_name("norm", PC=0.5, alpha=0.05)
    return np.asarray(sigmoid(level_D, location_D, width_D, GUESS_2AFC, lapse), float)


def aggregate_blocks(levels_D: np.ndarray, correct: np.ndarray) -> np.ndarray:
    """Trial-wise (level, correct) -> psignifit's ``[level, n_correct, n_total]`` rows."""
    levels_D = np.asarray(levels_D, float)
    correct = np.asarray(correct, float)
    unique = np.unique(levels_D)
    rows = [(lv, correct[levels_D == lv].sum(), (levels_D == lv).sum()) for lv in unique]
    return np.array(rows, float).reshape(-1, 3)


def _no_fit(data: np.ndarray, flags: tuple[str, ...]) -> PsychometricFit:
    nan = float("nan")
    levels = data[:, 0] if len(data) else np.array([nan])
    return PsychometricFit(
        nan, nan, nan, nan, nan, nan, nan, nan, nan, nan,
        n_levels=len(data), n_trials=int(data[:, 2].sum()) if len(data) else 0,
        level_min_D=float(np.min(levels)), level_max_D=float(np.max(levels)), flags=flags,
    )


def _weighted_quantiles(values: np.ndarray, weights: np.ndarray, qs: Sequence[float]) -> np.ndarray:
    order = np.argsort(values)
    v, w = values[order], weights[order]
    cdf = np.cumsum(w)
    cdf /= cdf[-1]
    return np.array([v[min(np.searchsorted(cdf, q), len(v) - 1)] for q in qs])


@dataclass(frozen=True)
class GridPosterior:
    """psignifit's dense-grid posterior with the derived 75 %-correct level per grid point."""

    mesh: dict[str, np.ndarray]
    posterior: np.ndarray
    t75_D: np.ndarray
    grid: dict[str, np.ndarray]
    bounds: dict[str, tuple[float, float]]
    grid_max: dict[str, float]
    names: list[str]


def grid_posterior(data: np.ndarray, options: FitOptions = FitOptions()) -> GridPosterior:
    """Run psignifit's pipeline up to the dense-grid posterior (no Nelder-Mead MAP refinement)."""
    grid_spec = options.grid
    fixed = {name: value for name, value in (("lambda", options.fixed_lambda), ("eta", options.fixed_eta))
             if value is not None} or None
    conf = psignifit.Configuration(
        experiment_type="2AFC", sigmoid="norm", verbose=False, fixed_parameters=fixed,
        grid_steps=grid_spec.grid_steps(), steps_moving_bounds=grid_spec.sparse_steps(),
        confP=(options.ci_level,),
    )
    sigmoid = conf.make_sigmoid()
    levels = data[:, 0]
    stimulus_range = (levels.min(), levels.max())
    width_min = np.diff(np.unique(levels)).min()
    bounds = parameter_bounds(
        min_width=width_min, experiment_type=conf.experiment_type, stimulus_range=stimulus_range,
        alpha=conf.width_alpha, nafc_choices=conf.experiment_choices,
    )
    for name, value in (fixed or {}).items():
        bounds[name] = (value, value)
    priors = setup_priors(
        custom_priors=None, bounds=bounds, stimulus_range=stimulus_range, width_min=width_min,
        width_alpha=conf.width_alpha, beta_prior=conf.beta_prior, threshold_prop_correct=conf.thresh_PC,
    )
    sparse = parameter_grid(bounds, conf.steps_moving_bounds)
    post_sparse, _ = posterior_grid(data, sigmoid=sigmoid, priors=priors, grid=sparse)
    tight = masked_parameter_bounds(sparse, post_sparse >= conf.max_bound_value)
    grid = parameter_grid(tight, conf.grid_steps)
    post, grid_max = posterior_grid(data, sigmoid=sigmoid, priors=priors, grid=grid)

    names = sorted(grid)  # psignifit orders posterior axes alphabetically
    mesh = dict(zip(names, np.meshgrid(*[np.atleast_1d(grid[n]) for n in names], indexing="ij")))
    gamma = mesh["gamma"]
    with np.errstate(invalid="ignore", divide="ignore"):
        scaled = (TARGET_PC - gamma) / (1.0 - mesh["lambda"] - gamma)
        t75 = sigmoid._inverse(np.clip(scaled, 0.0, 1.0), mesh["threshold"], mesh["width"])
    t75 = np.where(np.isfinite(t75), t75, np.inf)
    for _ in range(options.map_refinements):
        grid_max = _refine_map(data, sigmoid, priors, grid, grid_max)
    return GridPosterior(mesh, post, t75, grid, bounds, grid_max, names)


def _refine_map(data, sigmoid, priors, grid, grid_max, points: int = 7) -> dict[str, float]:
    """Zoom into the posterior mode: a finer grid spanning one dense step either side.

    Replaces psignifit's scalar Nelder-Mead MAP search by one vectorised grid evaluation.
    """
    local = {}
    for name, values in grid.items():
        values = np.atleast_1d(values)
        if len(values) < 2:
            local[name] = values
            continue
        i = int(np.argmin(np.abs(values - grid_max[name])))
        step = values[1] - values[0] if i == 0 else values[i] - values[i - 1]
        lo = max(values[0], grid_max[name] - step)
        hi = min(values[-1], grid_max[name] + step)
        local[name] = np.linspace(lo, hi, points)
    _, best = posterior_grid(data, sigmoid=sigmoid, priors=priors, grid=local)
    return best


def _t75(params: dict[str, float]) -> float:
    """Level where the 2AFC curve of ``params`` reaches 75 % correct (inf if it never does)."""
    scaled = (TARGET_PC - params["gamma"]) / (1.0 - params["lambda"] - params["gamma"])
    if not 0.0 < scaled < 1.0:
        return float("inf")
    return float(params["threshold"] + norm.ppf(scaled) * params["width"] / (2.0 * norm.ppf(0.95)))


def fit_psychometric(data: np.ndarray, options: FitOptions = FitOptions()) -> PsychometricFit:
    """Fit a 2AFC cumulative normal to ``data`` (rows ``[level_D, n_correct, n_total]``).

    Follows ``psignifit.psignifit`` step by step (same Configuration, bounds, priors,
    sparse grid -> tightened bounds -> dense grid) and summarises the dense-grid posterior.
    """
    data = np.asarray(data, float).reshape(-1, 3)
    data = data[data[:, 2] > 0]
    if len(np.unique(data[:, 0])) < 2:
        return _no_fit(data, ("fewer_than_two_levels",))
    post_ = grid_posterior(data, options)
    post, t75, grid, bounds, names = post_.posterior, post_.t75_D, post_.grid, post_.bounds, post_.names
    grid_max = post_.grid_max
    levels = data[:, 0]
    weights = post.ravel()
    half = (1.0 - options.ci_level) / 2.0
    low, high = _weighted_quantiles(t75.ravel(), weights, (half, 1.0 - half))
    threshold = float(_t75(grid_max))

    width = float(grid_max["width"])
    lapse = float(grid_max["lambda"])
    location = float(grid_max["threshold"])
    best_pc = predicted_pc(levels, grid_max["threshold"], grid_max["width"], grid_max["lambda"])
    gof = deviance_test(data[:, 1], data[:, 2], best_pc, options.n_bootstrap, options.seed)

    eta = float(grid_max["eta"])
    if options.fixed_eta is not None:
        eta = float("nan")
        if options.estimate_eta:
            free = grid_posterior(data, replace(options, fixed_eta=None))
            eta = float((free.mesh["eta"] * free.posterior).sum())

    flags: list[str] = []
    if np.all(data[:, 1] == data[:, 2]):
        flags.append("all_correct")
    if not (levels.min() <= threshold <= levels.max()):
        flags.append("threshold_outside_range")
    for name in ("threshold", "width"):
        axis = names.index(name)
        marginal = post.sum(axis=tuple(i for i in range(post.ndim) if i != axis))
        marginal = marginal / marginal.sum()
        at_bound = np.isclose(grid[name][[0, -1]], bounds[name])
        if (at_bound & (marginal[[0, -1]] > EDGE_MASS)).any():
            flags.append("posterior_at_grid_edge")
            break
    # psignifit's 'norm' width spans the 5 %-95 % points of the unscaled sigmoid: 2 * 1.645 sd
    sigma = width / (2.0 * float(norm.ppf(0.95)))
    return PsychometricFit(
        threshold_D=threshold, threshold_ci_low_D=float(low), threshold_ci_high_D=float(high),
        width_D=width, sigma_D=float(sigma), location_D=location, lapse=lapse, eta=eta,
        deviance=gof.deviance, deviance_p=gof.p_value, n_levels=len(data), n_trials=int(data[:, 2].sum()),
        level_min_D=float(levels.min()), level_max_D=float(levels.max()), flags=tuple(flags),
    )


def _fit_task(args: tuple[np.ndarray, FitOptions]) -> PsychometricFit:
    return fit_psychometric(*args)


def fit_many(datasets: Sequence[np.ndarray], options: FitOptions = FitOptions(), n_jobs: int = 1) -> list[PsychometricFit]:
    """Fit every dataset; ``n_jobs`` > 1 spreads fits over processes (-1: all cores)."""
    if n_jobs < 0:
        n_jobs = os.cpu_count() or 1
    tasks = [(np.asarray(d, float), options) for d in datasets]
    if n_jobs == 1 or len(tasks) < 2:
        return [fit_psychometric(*t) for t in tasks]
    with ProcessPoolExecutor(max_workers=min(n_jobs, len(tasks))) as pool:
        return list(pool.map(_fit_task, tasks, chunksize=max(1, len(tasks) // (4 * n_jobs))))


FIT_COLUMNS = [
    "threshold_D", "threshold_ci_low_D", "threshold_ci_high_D", "width_D", "sigma_D", "location_D",
    "lapse", "eta", "deviance", "deviance_p", "n_levels", "n_trials", "level_min_D", "level_max_D",
]


def fit_psychometric_table(
    trials: pd.DataFrame,
    level_column: str = "level_D",
    group_columns: Sequence[str] = ("participant", "back_D"),
    correct_column: str = "correct",
    options: FitOptions = FitOptions(),
    n_jobs: int = 1,
) -> pd.DataFrame:
    """One row per group (e.g. subject x condition) with threshold, CI, width, lapse, eta, GOF, flags.

    Trials with a null ``correct`` (no response) are dropped and counted in ``n_missing``.
    ``flags`` is a ';'-joined string ('' when the fit is clean) so the table stays CSV-friendly.
    """
    group_columns = list(group_columns)
    missing = [c for c in [level_column, correct_column, *group_columns] if c not in trials]
    if missing:
        raise KeyError(f"trials lack columns {missing}")
    keys, datasets, n_missing = [], [], []
    for key, group in trials.groupby(group_columns, sort=True):
        answered = group[group[correct_column].notna()]
        keys.append(key if isinstance(key, tuple) else (key,))
        n_missing.append(len(group) - len(answered))
        datasets.append(aggregate_blocks(answered[level_column].to_numpy(float), answered[correct_column].to_numpy(bool)))
    fits = fit_many(datasets, options, n_jobs)
    rows = []
    for key, fit, miss in zip(keys, fits, n_missing):
        row = dict(zip(group_columns, key))
        row.update({c: getattr(fit, c) for c in FIT_COLUMNS})
        row["n_missing"] = miss
        row["flags"] = ";".join(fit.flags)
        rows.append(row)
    return pd.DataFrame(rows)
