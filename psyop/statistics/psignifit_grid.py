"""psyop's posterior-grid engine: psignifit's pipeline (its Configuration, parameter bounds, default
priors, sparse grid -> tightened bounds -> dense grid), then a posterior grid refined around the mass
and the modes zoomed into (docs/statistics.md, "How it uses psignifit").

psignifit's private functions come only through :mod:`psyop.statistics.psignifit_private`; the
model is :mod:`psyop.statistics.psignifit_posterior`, the modes :mod:`psyop.statistics.posterior_modes`.
:func:`posterior_on_grid` takes a :class:`GridRequest` (what a fit's options ask of the grid).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np
import psignifit

from psyop.statistics.posterior_modes import _find_modes
from psyop.statistics.psignifit_posterior import (
    _t75_grid, _t75_mesh, _target_kwargs, log_posterior_2afc, posterior_2afc, tabulate_priors,
)
from psyop.statistics.psignifit_private import masked_parameter_bounds, parameter_bounds, setup_priors

#: Mass of a normalised marginal at the outermost grid point above which the posterior
#: is considered cut by the grid (psignifit's own sanity-check value).
EDGE_MASS = 1e-3
#: The refined posterior grid is refined again until each axis's central 95 % spans this many points.
MIN_CI_POINTS = 10
#: Tail mass left outside a refined grid, per side and axis.
REFINE_TAIL = 1e-5
#: A grid edge (no prior bound) whose marginal holds more than this cuts the posterior and moves out
#: (psignifit's own edge value: smaller tails moved out made 15-trial CIs no closer to a 2.5x grid's).
CUT_MASS = EDGE_MASS
#: At most this many moves of a grid edge that cuts the posterior mass (:func:`refine_posterior`).
MAX_GRID_MOVES = 8


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
class GridPosterior:
    """psignifit's posterior on a grid, with the derived 75 %-correct level per grid point.

    ``dense_*`` keep the psignifit dense-grid posterior (bound checks, bimodality); ``mesh``,
    ``posterior``, ``t75_D`` and ``grid`` are the refined grid the CI is read from.
    """

    mesh: dict[str, np.ndarray]
    posterior: np.ndarray
    t75_D: np.ndarray
    grid: dict[str, np.ndarray]
    bounds: dict[str, tuple[float, float]]
    grid_max: dict[str, float]
    names: list[str]
    dense_grid: dict[str, np.ndarray]
    dense_posterior: np.ndarray
    dense_t75_D: np.ndarray
    n_refinements: int
    #: distinct local maxima (log posterior, parameters), best first; ``grid_max`` is the first
    modes: tuple[tuple[float, dict[str, float]], ...] = ()
    #: free axes whose mass the final grid still cuts at an edge that is no prior bound
    cut_axes: tuple[str, ...] = ()
    #: how often a cutting grid edge was moved out (:func:`refine_posterior`)
    n_moves: int = 0
    #: psignifit's normalised priors (tabulated, :func:`tabulate_priors`) the posterior was computed with
    priors: dict[str, Callable[[np.ndarray], np.ndarray]] = field(default_factory=dict)


def _isclose(a: float, b: float) -> bool:
    """``np.isclose(a, b)`` (rtol 1e-5, atol 1e-8, NaN never close) for two scalars: NumPy's formula
    ``|a - b| <= atol + rtol |b|`` and b finite, or a == b, without its array handling."""
    return bool(a == b or (abs(a - b) <= 1e-8 + 1e-5 * abs(b) and math.isfinite(b)))


def _allclose(a: np.ndarray, b: np.ndarray) -> bool:
    """``np.allclose(a, b)`` (rtol 1e-5, atol 1e-8) written out: the same formula as :func:`_isclose`."""
    with np.errstate(invalid="ignore"):
        return bool(np.all((np.abs(a - b) <= 1e-8 + 1e-5 * np.abs(b)) & np.isfinite(b) | (a == b)))


def _parameter_grid(bounds: dict[str, tuple[float, float]], steps: dict[str, int]) -> dict[str, np.ndarray]:
    """psignifit's ``parameter_grid`` (``linspace`` over each bound, the bound's start alone where
    the bound is a point) with :func:`_isclose` for its ``np.isclose``."""
    return {name: np.array([bound[0]]) if _isclose(bound[0], bound[1]) else np.linspace(*bound, num=steps[name])
            for name, bound in bounds.items()}


def _marginal(post: np.ndarray, axis: int) -> np.ndarray:
    m = post.sum(axis=tuple(i for i in range(post.ndim) if i != axis))
    return m / m.sum()


def _cut_edges(values: np.ndarray, marginal: np.ndarray, bound: tuple[float, float]) -> tuple[bool, bool]:
    """Whether a marginal holds more than :data:`CUT_MASS` at its first / last grid point
    while that point is not the parameter's bound: the grid cuts the posterior there."""
    lo_cut = marginal[0] > CUT_MASS and values[0] > bound[0] and not _isclose(values[0], bound[0])
    hi_cut = marginal[-1] > CUT_MASS and values[-1] < bound[1] and not _isclose(values[-1], bound[1])
    return bool(lo_cut), bool(hi_cut)


def grid_cuts_posterior(grid: dict[str, np.ndarray], post: np.ndarray, bounds: dict[str, tuple[float, float]]
                        ) -> list[str]:
    """The free axes whose posterior mass the grid cuts off at an edge that is not a prior bound."""
    names = sorted(grid)
    cut = []
    for axis, name in enumerate(names):
        values = np.atleast_1d(grid[name])
        if len(values) > 1 and any(_cut_edges(values, _marginal(post, axis), bounds[name])):
            cut.append(name)
    return cut


def refine_posterior(grid: dict[str, np.ndarray], post: np.ndarray, bounds: dict[str, tuple[float, float]],
                     move_D: dict[str, float] | None = None) -> tuple[dict[str, np.ndarray], bool]:
    """A grid spanning each free axis's posterior mass (tails <= :data:`REFINE_TAIL` cut) with
    the same number of points; ``done`` is True when the threshold and width axes already resolve
    their central 95 % with >= :data:`MIN_CI_POINTS` points (or half the axis) and no axis's
    mass is cut by the grid.

    Where the grid cuts the mass at an edge that is not a prior bound (psignifit's bounds,
    tightened on its sparse grid, can exclude the mode: with thousands of trials per level
    the sparse grid's best cell lies on a lapse row next to the true one, and the tightened
    box around it excludes the true width), that edge moves outwards by ``move_D[axis]``
    (default: the axis's span), clipped to the bound, so repeated calls walk the grid to the mass.
    """
    names = sorted(grid)
    new, done = {}, True
    for axis, name in enumerate(names):
        values = np.atleast_1d(grid[name])
        if len(values) < 2:
            new[name] = grid[name]
            continue
        marginal = _marginal(post, axis)
        cdf = np.cumsum(marginal)
        inner = np.searchsorted(cdf, [0.025, 0.975])
        if name in ("threshold", "width") and inner[1] - inner[0] + 1 < min(MIN_CI_POINTS, len(values) // 2):
            done = False
        lo_i = max(int(np.searchsorted(cdf, REFINE_TAIL)) - 1, 0)
        hi_i = min(int(np.searchsorted(cdf, 1.0 - REFINE_TAIL)) + 1, len(values) - 1)
        lo, hi = values[lo_i], values[hi_i]
        lo_cut, hi_cut = _cut_edges(values, marginal, bounds[name])
        move = (move_D or {}).get(name, values[-1] - values[0])
        if lo_cut:
            lo, done = values[0] - move, False
        if hi_cut:
            hi, done = values[-1] + move, False
        lo, hi = max(lo, bounds[name][0]), min(hi, bounds[name][1])
        new[name] = np.linspace(lo, hi, len(values)) if hi > lo else values
    unchanged = all(_allclose(np.atleast_1d(new[n]), np.atleast_1d(grid[n])) for n in names)
    return new, done or unchanged


def _edge_mass(grid, post, bounds, names) -> bool:
    """psignifit's own sanity check: the threshold or width marginal holds more than :data:`EDGE_MASS` at a
    grid edge that is the parameter's prior bound."""
    for name in ("threshold", "width"):
        axis = names.index(name)
        marginal = _marginal(post, axis)
        at_bound = np.array([_isclose(grid[name][0], bounds[name][0]), _isclose(grid[name][-1], bounds[name][1])])
        if (at_bound & (marginal[[0, -1]] > EDGE_MASS)).any():
            return True
    return False


#: (stimulus range, smallest level step, fixed parameters, configuration) -> (bounds, tabulated priors)
_PRIORS_CACHE: dict[tuple, tuple[dict[str, tuple[float, float]], dict]] = {}


def _bounds_and_priors(conf, levels: np.ndarray, fixed: dict[str, float] | None
                       ) -> tuple[dict[str, tuple[float, float]], dict]:
    """psignifit's parameter bounds (fixed parameters pinned) and its priors tabulated over them
    (:func:`tabulate_priors`) for these levels. Both are a function of the levels' range and smallest
    step and of ``conf`` alone, so they are computed once per distinct key and reused (a replication
    fits the same levels for every participant and condition; the tabulation was ~45 % of a fit)."""
    stimulus_range = (levels.min(), levels.max())
    width_min = np.diff(np.unique(levels)).min()
    key = (float(stimulus_range[0]), float(stimulus_range[1]), float(width_min), tuple(sorted((fixed or {}).items())),
           conf.experiment_type, conf.experiment_choices, conf.width_alpha, conf.beta_prior, conf.thresh_PC)
    cached = _PRIORS_CACHE.get(key)
    if cached is None:
        bounds = parameter_bounds(
            min_width=width_min, experiment_type=conf.experiment_type, stimulus_range=stimulus_range,
            alpha=conf.width_alpha, nafc_choices=conf.experiment_choices,
        )
        for name, value in (fixed or {}).items():
            bounds[name] = (value, value)
        priors = setup_priors(
            bounds=bounds, stimulus_range=stimulus_range, width_min=width_min,
            width_alpha=conf.width_alpha, beta_prior=conf.beta_prior, threshold_prop_correct=conf.thresh_PC,
        )
        if len(_PRIORS_CACHE) > 256:
            _PRIORS_CACHE.clear()
        cached = _PRIORS_CACHE[key] = (dict(bounds), tabulate_priors(priors, bounds))
    return dict(cached[0]), dict(cached[1])


#: (grid, fixed parameters, CI level) -> psignifit Configuration (read only, never modified)
_CONFIGURATION_CACHE: dict[tuple, psignifit.Configuration] = {}


def _configuration(grid_spec: GridSpec, fixed: dict[str, float] | None, ci_level: float,
                   experiment: str = "2AFC") -> psignifit.Configuration:
    """psignifit's 'norm' Configuration (``experiment``: psignifit's type, "2AFC", "4AFC", "yes/no") for
    these grid steps, fixed parameters and CI level, built once per distinct key: a fit only reads it
    (its steps, bound value and prior settings). A yes/no guess axis has psignifit's default steps."""
    key = (grid_spec, tuple(sorted((fixed or {}).items())), ci_level) + (() if experiment == "2AFC" else (experiment,))
    conf = _CONFIGURATION_CACHE.get(key)
    if conf is None:
        if len(_CONFIGURATION_CACHE) > 256:
            _CONFIGURATION_CACHE.clear()
        with warnings.catch_warnings():
            # psignifit warns of a fixed yes/no guess rate above 0.2; the caller chose it
            warnings.filterwarnings("ignore", message="You have fixed the guess rate gamma")
            conf = _CONFIGURATION_CACHE[key] = psignifit.Configuration(
                experiment_type=experiment, sigmoid="norm", verbose=False, fixed_parameters=fixed,
                grid_steps=grid_spec.grid_steps(), steps_moving_bounds=grid_spec.sparse_steps(),
                confP=(ci_level,),
            )
    return conf


@dataclass(frozen=True)
class GridRequest:
    """What a fit asks of the posterior grid: its resolution, the parameters fixed, psignifit's
    experiment type ("2AFC" .. "8AFC", "yes/no"), the CI level of psignifit's Configuration, the
    proportion the threshold is read at (None: the yes/no midpoint) and the refinement counts."""

    grid: GridSpec
    fixed: dict[str, float] | None
    experiment: str
    ci_level: float
    target_p: float | None
    map_refinements: int
    posterior_refinements: int


def posterior_on_grid(data: np.ndarray, request: GridRequest) -> GridPosterior:
    """psignifit's pipeline up to the dense-grid posterior, then the refined posterior and MAP."""
    fixed, experiment = request.fixed, request.experiment
    conf = _configuration(request.grid, fixed, request.ci_level, **({} if experiment == "2AFC" else
                                                                    {"experiment": experiment}))
    target_kw = _target_kwargs(request.target_p)
    bounds, priors = _bounds_and_priors(conf, data[:, 0], fixed)
    sparse = _parameter_grid(bounds, conf.steps_moving_bounds)
    post_sparse, _ = posterior_2afc(data, priors, sparse)
    tight = masked_parameter_bounds(sparse, post_sparse >= conf.max_bound_value)
    dense_grid = _parameter_grid(tight, conf.grid_steps)
    dense_lp = log_posterior_2afc(data, priors, dense_grid)
    dense_post, grid_max = posterior_2afc(data, priors, dense_grid, dense_lp)
    dense_t75, names = _t75_grid(dense_grid, **target_kw), sorted(dense_grid)

    grid, post, n_ref, lp = dense_grid, dense_post, 0, dense_lp
    # a grid edge that cuts the mass moves out in steps of the dense grid's span (at most
    # MAX_GRID_MOVES times); refinements for resolution are at most ``posterior_refinements``
    move_D = {n: float(np.ptp(np.atleast_1d(v))) for n, v in dense_grid.items()}
    n_moves = 0
    while True:
        cut = grid_cuts_posterior(grid, post, bounds)
        if cut and n_moves >= MAX_GRID_MOVES or not cut and n_ref - n_moves >= request.posterior_refinements:
            break
        new_grid, done = refine_posterior(grid, post, bounds, move_D)
        if done:
            break
        lp = log_posterior_2afc(data, priors, new_grid)
        post, grid_max = posterior_2afc(data, priors, new_grid, lp)
        grid, n_ref, n_moves = new_grid, n_ref + 1, n_moves + bool(cut)
    cut = grid_cuts_posterior(grid, post, bounds)
    mesh, t75, names = _t75_mesh(grid, **target_kw)
    modes = _find_modes(data, priors, grid, bounds, request.map_refinements, lp) if request.map_refinements else []
    grid_max = modes[0][1] if modes else grid_max
    return GridPosterior(mesh, post, t75, grid, bounds, grid_max, names, dense_grid, dense_post, dense_t75, n_ref,
                         tuple(modes), tuple(cut), n_moves, priors)
