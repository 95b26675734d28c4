"""nAFC and yes/no psychometric functions with psignifit 4.3 (cumulative normal on linear diopters).

The default (``FitOptions()``) is 2AFC: guess rate fixed at 0.5, threshold at 75 % correct.
Other response kinds (:class:`FitOptions` ``experiment`` and ``guess``; section "Response kinds"
below) run the same pipeline with psignifit's grid for their guess rate.

Why not simply ``psignifit.psignifit``: its last step refines the MAP with a Nelder-Mead
search whose objective calls ``scipy.stats.norm.ppf`` on scalars; that step is most of a
~1-2 s fit here, while the grid posterior (priors, bounds, credible intervals) costs tens
of ms. psyop runs psignifit's own pipeline (its Configuration, parameter bounds, default
priors, sparse grid -> tightened bounds -> dense grid), then

- **moves a grid edge that cuts the posterior** out to the mass (:func:`refine_posterior`,
  :data:`CUT_MASS`): with thousands of trials per level the bounds psignifit tightens on its
  sparse grid can exclude the mode, and a CI read inside them misses;
- **refines the posterior grid** around the posterior mass (:func:`refine_posterior`): the
  dense grid spans the tightened prior bounds, so with many trials per level the whole
  posterior falls between two grid points and a CI read off that grid collapses to the grid
  step. The refined grid spans the mass at the same number of points, repeated until each
  axis's central 95 % spans at least :data:`MIN_CI_POINTS` points;
- **zooms into the posterior mode** with vectorised grids (:func:`_refine_map`) instead of
  the scalar Nelder-Mead search;
- **confirms two grid peaks** by hill-climbs on the exact posterior (:func:`climbs_apart`)
  before calling a fit ``bimodal``.

Reported:

- ``threshold_D``: the 75 %-correct level of the MAP curve (what ``res.threshold(0.75)``
  returns for psignifit's MAP; lapse included, so it is *not* the 'threshold' parameter);
  **NaN unless the fit's status allows a number** (see below);
- ``threshold_ci_*_D``: 2.5/97.5 % posterior percentiles of the 75 %-correct level over the
  refined grid (interpolated); ``+inf`` when >= 2.5 % of the posterior are curves that never
  reach 75 % correct (status ``no_upper_bound``);
- width, lapse (MAP), eta (overdispersion; see :class:`FitOptions`), and a deviance test.

Status (exactly one per fit, the first that applies; :data:`STATUSES`):

``no_fit`` fewer than two tested levels (everything NaN);
``lapse_at_bound`` the MAP lapse is >= 0.25, so the MAP curve never reaches 75 % correct:
no threshold (NaN), censored above the highest level;
``censored_below`` the MAP 75 % point lies below the lowest tested level (e.g. all correct):
``threshold_D`` NaN, ``threshold_bound_D`` = lowest level, read "< lowest level";
``censored_above`` ... above the highest level (e.g. chance performance): NaN, "> highest level";
``bimodal`` the refined-grid posterior has two separated modes (:func:`separated_peaks`)
that climbs on the exact posterior do not join (:func:`climbs_apart`), or a second zoomed
mode's 75 % point differs; the MAP is then arbitrary between them;
``posterior_at_grid_edge`` the threshold or width marginal has > 0.1 % mass at a prior bound
(psignifit's own check), or the final grid still cuts the mass at an edge that is no bound;
``no_upper_bound`` the upper CI bound is infinite (threshold itself is in range);
``ok`` none of these.

``flags`` lists every condition that applies (the status among them), plus ``grid_peaks_joined``
(the grid showed separated peaks that hill-climbs on the exact posterior join: one mode, not
``bimodal``), ``all_correct``
and ``ci_below_range`` / ``ci_above_range`` (a CI bound beyond the tested levels: a posterior
percentile under the fitted model, kept as a number but never unflagged).

Analyses use :func:`usable_for_analysis` (statuses in :data:`USABLE_STATUSES`) and report
how many fits of each other status they left out.

Response kinds (:class:`FitOptions`; :func:`nafc_options`, :func:`yes_no_options`):

- **nAFC** (``experiment="nAFC"``, ``guess=1/n``, n = 2..8; psignifit's "nAFC" with gamma fixed
  at 1/n): rows are ``[level, n_correct, n_total]``. ``threshold_D`` is the level where the MAP
  curve (lapse included) reaches ``target_p = guess + (1 - guess) / 2`` (0.75 for 2AFC, 0.625 for
  4AFC), its CI the posterior percentiles of that level. The statuses read as above with
  ``target_p`` for 75 %: ``lapse_at_bound`` is a MAP lapse >= ``1 - target_p`` = (1 - guess) / 2
  (0.25 for 2AFC, 0.375 for 4AFC; psignifit's lapse bound is 0.5), ``censored_*`` the MAP
  ``target_p`` point beyond the tested levels, ``no_upper_bound`` >= 2.5 % of the posterior on
  curves that never reach ``target_p``. ``guess=0.5`` is the 2AFC path above, bit for bit.
- **yes/no** (``experiment="yes/no"``): rows are ``[level, n_yes, n_total]``. The guess
  (false-alarm) rate is fixed (``guess`` in [0, 1)) or free (``guess=None``: a grid parameter like
  the lapse, psignifit's yes/no bounds [0, 0.5] and prior Beta(1, 10), 20 dense / 10 sparse grid
  steps, its psignifit default; the posterior then has four free axes, and the CI marginalises over
  the guess rate). ``threshold_D`` is the 50 % point of the unscaled sigmoid (psignifit's
  'threshold' parameter, ``location_D``): the level where the MAP curve is halfway between its
  guess rate and ``1 - lapse``; ``target_p = guess + (1 - guess - lapse) / 2`` of the MAP curve
  (a fitted number when the guess or lapse is free). ``guess`` reports the MAP guess rate (or the
  fixed one). Statuses:

  ``lapse_at_bound``: the MAP curve has no midpoint, i.e. it is flat or falling
  (``guess + lapse >= 1``). The midpoint is relative to the fitted asymptotes, so a large lapse
  alone (an observer who never says "yes" more than half the time) does not censor it: with
  psignifit's bounds (guess <= 0.5, lapse <= 0.5) this happens only at their common corner, or with
  a fixed guess >= 0.5; read the ``lapse`` and ``guess`` fields for an absolute criterion.
  ``censored_below``: the MAP midpoint lies below the lowest level (e.g. all "yes": the curve has
  risen before the tested range); ``censored_above``: above the highest level (e.g. "yes" at the
  guess rate throughout: the curve has not started to rise); ``bimodal``, ``posterior_at_grid_edge``
  as above (the guess axis's edges are prior bounds, not cuts); ``no_upper_bound``: >= 2.5 % of the
  posterior on flat or falling curves, which psignifit's bounds practically exclude, so a yes/no CI
  is finite. ``all_correct`` is "all yes".

  A fit's ``guess`` and ``target_p`` are new fields at the end of :class:`PsychometricFit`
  (defaults 0.5 and 0.75); :func:`fit_psychometric_table` adds them as columns only for options
  other than 2AFC, so 2AFC tables keep their columns.

Input rows are checked (:func:`validate_blocks`): NaN levels or counts, negative,
non-integer counts and n_correct > n_total raise :class:`InvalidPsychometricData` naming the
rows.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field, replace

import numpy as np
import pandas as pd
import psignifit
from psignifit._parameter import masked_parameter_bounds, parameter_bounds
from psignifit._posterior import integral_weights
from psignifit._priors import setup_priors
from scipy import ndimage, optimize, special
from scipy.stats import norm

from psyop.errors import UserError
from psyop.statistics.goodness import deviance_test

#: Mass of a normalised marginal at the outermost grid point above which the posterior
#: is considered cut by the grid (psignifit's own sanity-check value).
EDGE_MASS = 1e-3
TARGET_PC = 0.75
GUESS_2AFC = 0.5
#: Response kinds (:class:`FitOptions` ``experiment``) and the nAFC choices allowed.
EXPERIMENTS = ("nAFC", "yes/no")
NAFC_CHOICES = range(2, 9)
#: A 2AFC curve with lapse >= this never reaches 75 % correct.
LAPSE_NO_THRESHOLD = 0.25
#: The refined posterior grid is refined again until each axis's central 95 % spans this many points.
MIN_CI_POINTS = 10
#: Tail mass left outside a refined grid, per side and axis.
REFINE_TAIL = 1e-5
#: A grid edge (no prior bound) whose marginal holds more than this cuts the posterior and moves out
#: (psignifit's own edge value: smaller tails moved out made 15-trial CIs no closer to a 2.5x grid's).
CUT_MASS = EDGE_MASS
#: At most this many moves of a grid edge that cuts the posterior mass (:func:`refine_posterior`).
MAX_GRID_MOVES = 8

STATUSES = ("no_fit", "lapse_at_bound", "censored_below", "censored_above", "bimodal",
            "posterior_at_grid_edge", "no_upper_bound", "ok")
#: Statuses whose ``threshold_D`` is a point estimate inside the tested range that analyses use.
USABLE_STATUSES = ("ok", "no_upper_bound")


class InvalidPsychometricData(UserError):
    """Rows of ``[level, n_correct, n_total]`` that cannot be fitted, named by row."""


class InvalidFitOptions(UserError):
    """A :class:`FitOptions` that names no fit: an unknown response kind or a guess rate it cannot have."""


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
    #: eta = 0 coverage is ~0.95 (docs/statistics.md). Overdispersion is still estimated
    #: (``estimate_eta``) and tested by the deviance bootstrap.
    fixed_eta: float | None = 0.0
    estimate_eta: bool = True
    ci_level: float = 0.95
    n_bootstrap: int = 2000
    seed: int = 0
    #: zoom-in grids around the posterior mode (each shrinks the step seven-fold)
    map_refinements: int = 4
    #: at most this many posterior-grid refinements for the credible interval
    posterior_refinements: int = 3
    #: response kind (module docstring, "Response kinds"): "nAFC" (proportion correct, guess fixed at
    #: 1/n) or "yes/no" (proportion of "yes" answers)
    experiment: str = "nAFC"
    #: guess rate: nAFC 1/n for n = 2..8 (0.5: 2AFC, the default; 0.25: 4AFC); yes/no a fixed
    #: false-alarm rate in [0, 1), or None: free (estimated on the grid like the lapse)
    guess: float | None = GUESS_2AFC

    def __post_init__(self) -> None:
        where = "FitOptions"
        if self.experiment not in EXPERIMENTS:
            raise InvalidFitOptions(f"experiment must be one of {EXPERIMENTS}, got {self.experiment!r}", where)
        g = self.guess
        if g is None:
            if self.experiment != "yes/no":
                raise InvalidFitOptions("a free guess rate (guess=None) needs experiment='yes/no'; an nAFC guess "
                                        "rate is 1/n", where)
            return
        if isinstance(g, bool) or not isinstance(g, (int, float, np.floating, np.integer)) \
                or not 0.0 <= float(g) < 1.0:
            raise InvalidFitOptions(f"guess rate must be a number in [0, 1) or None (free, yes/no), got {g!r}", where)
        if self.experiment == "nAFC":
            n = _nafc_choices(float(g))
            if n is None:
                raise InvalidFitOptions(
                    f"an nAFC guess rate is 1/n for n = 2..8, got {g!r}; for another fixed guess rate use "
                    "experiment='yes/no'", where)
            object.__setattr__(self, "guess", 1.0 / n)  # psignifit's 1/n exactly (0.5 for 2AFC)
        if self.experiment == "yes/no" and self.fixed_lambda is not None and not float(g) + self.fixed_lambda < 1.0:
            raise InvalidFitOptions(f"guess + fixed_lambda must be < 1, got {g!r} + {self.fixed_lambda!r}", where)

    @property
    def target_p(self) -> float | None:
        """nAFC: the proportion correct at threshold, ``guess + (1 - guess) / 2`` (0.75 for 2AFC); yes/no:
        None (the threshold is the midpoint of the fitted curve, whose proportion depends on the fit)."""
        if self.experiment == "yes/no":
            return None
        assert self.guess is not None
        g = float(self.guess)
        return g + (1.0 - g) / 2.0


def _nafc_choices(guess: float) -> int | None:
    """n where ``guess`` is 1/n (to 1e-9) for n in :data:`NAFC_CHOICES`, else None."""
    if guess <= 0.0:
        return None
    n = int(round(1.0 / guess))
    return n if n in NAFC_CHOICES and abs(guess - 1.0 / n) <= 1e-9 else None


def nafc_options(n: int, **kwargs) -> FitOptions:
    """:class:`FitOptions` for an n-alternative forced choice (guess 1/n, threshold at ``(1 + 1/n) / 2``)."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n not in NAFC_CHOICES:
        raise InvalidFitOptions(f"nAFC needs n = 2..8 choices, got {n!r}", "FitOptions")
    return FitOptions(experiment="nAFC", guess=1.0 / int(n), **kwargs)


def yes_no_options(guess: float | None = None, **kwargs) -> FitOptions:
    """:class:`FitOptions` for yes/no responses: guess (false-alarm) rate fixed, or free (None)."""
    return FitOptions(experiment="yes/no", guess=guess, **kwargs)


@dataclass(frozen=True)
class PsychometricFit:
    """One psychometric fit (2AFC by default; nAFC or yes/no, module docstring). Levels in diopters;
    NaN where the status allows no number."""

    status: str
    threshold_D: float
    threshold_ci_low_D: float
    threshold_ci_high_D: float
    #: censored fits: the tested level the threshold lies beyond (NaN otherwise)
    threshold_bound_D: float
    width_D: float  # psignifit width: distance between the 5 % and 95 % points of the unscaled sigmoid
    sigma_D: float  # sd of the cumulative normal (width / WIDTH_PER_SIGMA)
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
    #: guess rate: the fixed one, or the MAP of a free yes/no guess rate
    guess: float = GUESS_2AFC
    #: proportion (correct, or "yes") of the MAP curve at ``threshold_D``'s definition: nAFC
    #: ``guess + (1 - guess) / 2``; yes/no ``guess + (1 - guess - lapse) / 2``
    target_p: float = TARGET_PC

    @property
    def ci_width_D(self) -> float:
        return self.threshold_ci_high_D - self.threshold_ci_low_D

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def usable(self) -> bool:
        return self.status in USABLE_STATUSES

    @property
    def threshold_text(self) -> str:
        """The threshold as a reader should see it: a number, or a censored bound."""
        return threshold_text(self.status, self.threshold_D, self.threshold_bound_D)

    def proportion_correct(self, level_D: np.ndarray) -> np.ndarray:
        """The fitted curve (the fit's guess rate and lapse) at ``level_D``: proportion correct, or "yes"."""
        return predicted_pc(np.asarray(level_D, float), self.location_D, self.width_D, self.lapse, self.guess)


def threshold_text(status: str, threshold_D: float, bound_D: float) -> str:
    """'0.36 D', '< 0.00 D' (censored below), '> 1.00 D' (censored above), 'no fit'."""
    if status == "no_fit":
        return "no fit"
    if status == "censored_below":
        return f"< {bound_D:.2f} D"
    if status in ("censored_above", "lapse_at_bound"):
        return f"> {bound_D:.2f} D"
    return f"{threshold_D:.2f} D"


def predicted_pc(level_D: np.ndarray, location_D: float, width_D: float, lapse: float,
                 guess: float = GUESS_2AFC) -> np.ndarray:
    """Proportion correct (or "yes") of psignifit's 'norm' sigmoid with guess rate ``guess`` (2AFC: 0.5).

    psignifit's ``Gaussian(PC=0.5, alpha=0.05)(level_D, location_D, width_D, guess, lapse)`` with its
    ``scipy.stats.norm`` calls written out (:func:`_norm_standard_parameters`, ``norm.cdf`` is
    ``ndtr((x - loc) / scale)`` where scale > 0, NaN elsewhere): the same operations in the same order,
    so the same numbers, without scipy.stats' per-call argument handling.
    """
    scale, loc = _norm_standard_parameters(location_D, width_D)
    with np.errstate(invalid="ignore", divide="ignore"):
        value = np.where(scale > 0, special.ndtr((np.asarray(level_D) - loc) / scale), np.nan)
        value = guess + (1.0 - lapse - guess) * value
    return np.asarray(value, float)


def aggregate_blocks(levels_D: np.ndarray, correct: np.ndarray) -> np.ndarray:
    """Trial-wise (level, correct) -> psignifit's ``[level, n_correct, n_total]`` rows."""
    levels_D = np.asarray(levels_D, float)
    correct = np.asarray(correct, float)
    unique = np.unique(levels_D)
    rows = [(lv, correct[levels_D == lv].sum(), (levels_D == lv).sum()) for lv in unique]
    return np.array(rows, float).reshape(-1, 3)


def _rows(mask: np.ndarray) -> str:
    idx = np.flatnonzero(mask)
    shown = ", ".join(str(i) for i in idx[:10])
    return f"row{'s' if len(idx) > 1 else ''} {shown}{' ...' if len(idx) > 10 else ''}"


def validate_blocks(data: np.ndarray, source: str = "psychometric data") -> np.ndarray:
    """Check ``[level_D, n_correct, n_total]`` rows; return them as a float array.

    Raises :class:`InvalidPsychometricData` naming the 0-based rows with a NaN/inf level
    or count, a negative or non-integer count, or n_correct > n_total.
    """
    arr = np.asarray(data, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InvalidPsychometricData(f"expected rows of [level_D, n_correct, n_total], got shape {arr.shape}", source)
    problems = []
    level, k, n = arr[:, 0], arr[:, 1], arr[:, 2]
    checks = [
        (~np.isfinite(level), "level is NaN or infinite"),
        (~np.isfinite(k), "n_correct is NaN or infinite"),
        (~np.isfinite(n), "n_total is NaN or infinite"),
    ]
    finite = np.isfinite(k) & np.isfinite(n)
    checks += [
        (finite & ((k < 0) | (n < 0)), "negative count"),
        (finite & ((k != np.round(k)) | (n != np.round(n))), "non-integer count"),
        (finite & (k > n), "n_correct > n_total"),
    ]
    for mask, what in checks:
        if mask.any():
            problems.append(f"{what} in {_rows(mask)}")
    if problems:
        raise InvalidPsychometricData(
            "; ".join(problems) + " (counts must be whole numbers 0 <= n_correct <= n_total; levels finite)", source)
    return arr


def _no_fit(data: np.ndarray, flags: tuple[str, ...], options: FitOptions = FitOptions()) -> PsychometricFit:
    nan = float("nan")
    levels = data[:, 0] if len(data) else np.array([nan])
    target = options.target_p
    return PsychometricFit(
        "no_fit", nan, nan, nan, nan, nan, nan, nan, nan, nan, nan, nan,
        n_levels=len(data), n_trials=int(data[:, 2].sum()) if len(data) else 0,
        level_min_D=float(np.min(levels)), level_max_D=float(np.max(levels)), flags=("no_fit", *flags),
        guess=nan if options.guess is None else float(options.guess), target_p=nan if target is None else target,
    )


def weighted_quantiles(values: np.ndarray, weights: np.ndarray, qs: Sequence[float]) -> np.ndarray:
    """Quantiles of a weighted sample, interpolated between the sorted values' mid-cumulative weights.

    ``+inf`` values (curves that never reach the target) sort last; a quantile falling among
    them is ``+inf``.
    """
    values = np.asarray(values, float).ravel()
    weights = np.asarray(weights, float).ravel()
    keep = weights > 0
    values, weights = values[keep], weights[keep]
    order = np.argsort(values, kind="stable")
    v, w = values[order], weights[order]
    cdf = (np.cumsum(w) - 0.5 * w) / w.sum()
    out = []
    for q in qs:
        i = int(np.searchsorted(cdf, q))
        if i == 0:
            out.append(v[0])
        elif i >= len(v):
            out.append(v[-1])
        elif not np.isfinite(v[i]) or not np.isfinite(v[i - 1]):
            out.append(v[i])
        else:
            frac = (q - cdf[i - 1]) / (cdf[i] - cdf[i - 1])
            out.append(v[i - 1] + frac * (v[i] - v[i - 1]))
    return np.array(out, float)


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


_NORM_SPAN = float(norm.ppf(0.95) - norm.ppf(0.05))  # psignifit 'norm' width: 5 %-95 % of the unscaled sigmoid
_PPF_HALF = float(special.ndtri(0.5))  # 0.0: psignifit's Gaussian loc is threshold - ndtri(PC=0.5) * scale
WIDTH_PER_SIGMA = 2.0 * float(norm.ppf(0.95))  # width (5 %-95 % of the cumulative normal) over its sigma, 3.2897...
# _NORM_SPAN is the same quantity written ppf(0.95) - ppf(0.05); it is 1 ulp larger than WIDTH_PER_SIGMA and
# kept as it is so the fits stay bit-identical.


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
            custom_priors=None, bounds=bounds, stimulus_range=stimulus_range, width_min=width_min,
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


def _psignifit_experiment(options: FitOptions) -> str:
    """psignifit's experiment type for ``options``: "2AFC" .. "8AFC" or "yes/no"."""
    if options.experiment == "yes/no":
        return "yes/no"
    assert options.guess is not None
    return f"{_nafc_choices(float(options.guess))}AFC"


def _fixed_parameters(options: FitOptions) -> dict[str, float] | None:
    """The parameters ``options`` fix (lambda, eta; a yes/no guess rate as gamma), None if none."""
    pairs = [("lambda", options.fixed_lambda), ("eta", options.fixed_eta)]
    if options.experiment == "yes/no" and options.guess is not None:
        pairs.append(("gamma", float(options.guess)))
    return {name: value for name, value in pairs if value is not None} or None


def grid_posterior(data: np.ndarray, options: FitOptions = FitOptions()) -> GridPosterior:
    """psignifit's pipeline up to the dense-grid posterior, then the refined posterior and MAP."""
    grid_spec = options.grid
    fixed = _fixed_parameters(options)
    experiment = _psignifit_experiment(options)
    conf = _configuration(grid_spec, fixed, options.ci_level, **({} if experiment == "2AFC" else
                                                                 {"experiment": experiment}))
    target_kw = _target_kwargs(options.target_p)
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
        if cut and n_moves >= MAX_GRID_MOVES or not cut and n_ref - n_moves >= options.posterior_refinements:
            break
        new_grid, done = refine_posterior(grid, post, bounds, move_D)
        if done:
            break
        lp = log_posterior_2afc(data, priors, new_grid)
        post, grid_max = posterior_2afc(data, priors, new_grid, lp)
        grid, n_ref, n_moves = new_grid, n_ref + 1, n_moves + bool(cut)
    cut = grid_cuts_posterior(grid, post, bounds)
    mesh, t75, names = _t75_mesh(grid, **target_kw)
    modes = _find_modes(data, priors, grid, bounds, options.map_refinements, lp) if options.map_refinements else []
    grid_max = modes[0][1] if modes else grid_max
    return GridPosterior(mesh, post, t75, grid, bounds, grid_max, names, dense_grid, dense_post, dense_t75, n_ref,
                         tuple(modes), tuple(cut), n_moves, priors)


def _local_maxima(values: np.ndarray) -> np.ndarray:
    """``values == maximum_filter(values, size=3, mode="nearest")``: every point >= its 3^d grid
    neighbourhood. The filter runs on the axes longer than 1 only (along an axis of length 1 its
    'nearest' neighbourhood is the point itself), so the answer is the same."""
    core = values.reshape([s for s in values.shape if s > 1] or [1])
    return (core == ndimage.maximum_filter(core, size=3, mode="nearest")).reshape(values.shape)


def _find_modes(data, priors, grid, bounds, zooms: int, lp: np.ndarray, max_starts: int = 4,
                min_log_ratio: float = -1.0) -> list[tuple[float, dict[str, float]]]:
    """Local posterior maxima: every grid local maximum within ``min_log_ratio`` of the highest
    (at most ``max_starts``), each zoomed into ``zooms`` times; distinct modes, best first.

    psignifit starts one Nelder-Mead search at the grid maximum; two modes a few hundredths
    of a log unit apart can swap places on a grid, so psyop zooms from each candidate.
    """
    finite = np.where(np.isfinite(lp), lp, -np.inf)
    is_max = _local_maxima(finite) & (finite >= finite.max() + min_log_ratio)
    starts = sorted(np.argwhere(is_max), key=lambda i: -finite[tuple(i)])[:max_starts]
    names = sorted(grid)
    steps = {n: (np.ptp(np.atleast_1d(grid[n])) / max(len(np.atleast_1d(grid[n])) - 1, 1)) for n in names}
    # 15 points per free axis shrink the box seven-fold per zoom; with eta free (4 axes) 9 points
    # (four-fold) keep each zoom at ~6,500 points, and 1.4x the zooms reach the same resolution.
    n_free = sum(len(np.atleast_1d(grid[n])) > 1 for n in names)
    points = 15 if n_free <= 3 else 9
    zooms = zooms if n_free <= 3 else int(np.ceil(zooms * np.log(7) / np.log(4)))
    modes: list[tuple[float, dict[str, float]]] = []
    for idx in starts:
        point = {n: float(np.atleast_1d(grid[n])[i]) for n, i in zip(names, idx)}
        zoom = grid
        for _ in range(zooms):
            zoom = _shrink(zoom, point, bounds, points)
            point = _refine_map(data, priors, zoom, point)
        value = float(log_posterior_2afc(data, priors, {k: np.atleast_1d(v) for k, v in point.items()}).max())
        same = [m for m in modes if all(abs(m[1][n] - point[n]) <= 0.5 * steps[n] for n in names)]
        if not same:
            modes.append((value, point))
    return sorted(modes, key=lambda m: -m[0])


def _shrink(grid: dict[str, np.ndarray], centre: dict[str, float], bounds, points: int = 15) -> dict[str, np.ndarray]:
    """The next MAP zoom box: +-1 step of ``grid`` around ``centre`` at ``points`` points."""
    out = {}
    for name, values in grid.items():
        values = np.atleast_1d(values)
        if len(values) < 2:
            out[name] = values
            continue
        step = (values[-1] - values[0]) / (len(values) - 1)
        lo = max(bounds[name][0], centre[name] - step)
        hi = min(bounds[name][1], centre[name] + step)
        out[name] = _linspace(lo, hi, points)
    return out


def _linspace(start: float, stop: float, num: int) -> np.ndarray:
    """``np.linspace(start, stop, num)`` for two float scalars and ``num >= 2``: NumPy's own steps
    (``arange(num) * step + start``, the last point ``stop``, and its ``/ div * delta`` where the step
    underflows to 0) without its argument handling."""
    delta = np.subtract(stop, start, dtype=float)
    div = num - 1
    y = np.arange(0, num, dtype=float)
    step = delta / div
    if step == 0:
        y /= div
        y *= delta
    else:
        y *= step
    y += start
    y[-1] = stop
    return y


def _refine_map(data, priors, local, grid_max) -> dict[str, float]:
    """One zoom into the posterior mode: the maximum of the posterior on the small grid ``local``
    (plus the current best point, so the posterior never decreases). Replaces psignifit's scalar
    Nelder-Mead MAP search by vectorised grid evaluations."""
    local = {n: _with_point(v, grid_max[n]) if len(np.atleast_1d(v)) > 1 else v for n, v in local.items()}
    return _grid_argmax(local, log_posterior_2afc(data, priors, local))[1]


def _with_point(values: np.ndarray, x: float) -> np.ndarray:
    """``np.unique(np.append(values, x))``: for strictly increasing ``values`` and a finite, non-zero
    ``x`` (no signed zero to pick between), ``x`` inserted at its sorted place unless already there;
    otherwise NumPy's."""
    values = np.asarray(values)
    if values.dtype == np.float64 and values.ndim == 1 and math.isfinite(x) and x != 0.0 \
            and bool((values[1:] > values[:-1]).all()):
        i = int(np.searchsorted(values, x))
        if i < len(values) and values[i] == x:
            return values.copy()
        return np.insert(values, i, x)
    return np.unique(np.append(values, x))


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


def separated_peaks(post: np.ndarray, min_ratio: float = 0.1, max_dip: float = 0.75) -> list[tuple[np.ndarray, np.ndarray]]:
    """Pairs (highest peak, other peak) of grid indices that :func:`is_bimodal` calls separated.

    Local maxima of the joint posterior (each >= its 3^d grid neighbourhood) with at least
    ``min_ratio`` of the highest density are candidates; two are separate modes when the
    density along the straight line between them (linear interpolation on the grid) drops
    below ``max_dip`` of the lower one.
    """
    p = np.asarray(post, float)
    if p.size == 0 or p.max() <= 0:
        return []
    p = p / p.max()
    is_max = _local_maxima(p) & (p >= min_ratio)
    peaks = np.argwhere(is_max)
    if len(peaks) < 2:
        return []
    top = peaks[np.argmax(p[tuple(peaks.T)])]
    pairs = []
    for other in peaks:
        dist = np.abs(other - top).max()
        if dist < 2:
            continue
        t = np.linspace(0.0, 1.0, 4 * int(dist) + 1)
        line = top[:, None] + (other - top)[:, None] * t[None, :]
        along = ndimage.map_coordinates(p, line, order=1, mode="nearest")
        if along.min() < max_dip * p[tuple(other)]:
            pairs.append((top, other))
    return pairs


def is_bimodal(post: np.ndarray, min_ratio: float = 0.1, max_dip: float = 0.75) -> bool:
    """Whether a grid posterior has two separated modes (the MAP is then arbitrary between them).

    See :func:`separated_peaks`. Two modes within a few hundredths of a log unit (e.g. a
    small-lapse shallow curve and a large-lapse steep one) are the typical case. On a grid, a
    narrow diagonal ridge also shows separated peaks; :func:`fit_psychometric` therefore
    confirms each pair by climbing the exact posterior (:func:`climbs_apart`).
    """
    p = np.squeeze(np.asarray(post, float))
    if p.ndim == 0:
        return False
    return bool(separated_peaks(p, min_ratio, max_dip))


def _climb(data, priors, grid: dict[str, np.ndarray], bounds, index: np.ndarray) -> np.ndarray:
    """The local maximum of the exact log posterior reached from grid point ``index`` (free axes
    only, in grid-step units)."""
    names = sorted(grid)
    free = [n for n in names if len(np.atleast_1d(grid[n])) > 1]
    start = {n: float(np.atleast_1d(grid[n])[i]) for n, i in zip(names, index)}
    step = np.array([np.ptp(grid[n]) / (len(grid[n]) - 1) for n in free])
    x0 = np.array([start[n] for n in free])
    lo = np.array([bounds[n][0] for n in free])
    hi = np.array([bounds[n][1] for n in free])

    def negative(u: np.ndarray) -> float:
        x = np.clip(x0 + u * step, lo, hi)
        point: dict[str, float | np.ndarray] = dict(start, **{n: np.atleast_1d(v) for n, v in zip(free, x)})
        value = float(log_posterior_2afc(data, priors, {k: np.atleast_1d(v) for k, v in point.items()}).max())
        return -value if np.isfinite(value) else 1e300

    res = optimize.minimize(negative, np.zeros(len(free)), method="Nelder-Mead",
                            bounds=list(zip((lo - x0) / step, (hi - x0) / step)),
                            options={"xatol": 1e-3, "fatol": 1e-9, "maxiter": 2000})
    return np.asarray(res.x, float)  # offset from ``index`` in grid steps


def climbs_apart(data, priors, grid: dict[str, np.ndarray], bounds, top: np.ndarray, other: np.ndarray) -> bool:
    """Whether hill-climbs on the exact posterior from two grid peaks end more than one grid step
    apart on some axis, i.e. whether the two peaks are two modes and not one ridge seen on a grid."""
    names = sorted(grid)
    free_axes = [i for i, n in enumerate(names) if len(np.atleast_1d(grid[n])) > 1]
    top_free = np.asarray(top)[free_axes].astype(float)
    other_free = np.asarray(other)[free_axes].astype(float)
    end_top = top_free + _climb(data, priors, grid, bounds, top)
    end_other = other_free + _climb(data, priors, grid, bounds, other)
    return bool(np.abs(end_top - end_other).max() > 1.0)


def _distinct_thresholds(modes, ci_width_D: float, min_log_ratio: float = -1.0, min_shift: float = 0.25,
                         target_kw: dict | None = None) -> bool:
    """A second posterior mode, within ``min_log_ratio`` of the best, whose 75 % point (``target_kw``:
    :func:`_target_kwargs`) differs from the best one's by more than ``min_shift`` of the CI width (or
    is unreachable)."""
    if len(modes) < 2:
        return False
    best_lp, best = modes[0]
    t_best = _t75(best, **(target_kw or {}))
    for lp, other in modes[1:]:
        if lp - best_lp < min_log_ratio:
            continue
        t_other = _t75(other, **(target_kw or {}))
        if not (np.isfinite(t_best) and np.isfinite(t_other)):
            return True
        if abs(t_other - t_best) > min_shift * (ci_width_D if np.isfinite(ci_width_D) else 0.0):
            return True
    return False


def _edge_mass(grid, post, bounds, names) -> bool:
    for name in ("threshold", "width"):
        axis = names.index(name)
        marginal = _marginal(post, axis)
        at_bound = np.array([_isclose(grid[name][0], bounds[name][0]), _isclose(grid[name][-1], bounds[name][1])])
        if (at_bound & (marginal[[0, -1]] > EDGE_MASS)).any():
            return True
    return False


def _fit_conditions(data: np.ndarray, gp, t_map: float, lapse: float, level_range: tuple[float, float],
                    ci: tuple[float, float], lapse_limit: float = LAPSE_NO_THRESHOLD,
                    target_kw: dict | None = None) -> tuple[list[str], bool]:
    """The status conditions a fit meets (in :data:`STATUSES` terms), and whether the posterior grid
    had separated peaks that turned out joined (the ``grid_peaks_joined`` flag). ``lapse_limit``: the
    lapse from which the MAP curve has no threshold (2AFC 0.25; module docstring, "Response kinds")."""
    lo_level, hi_level = level_range
    low, high = ci
    conditions: list[str] = []
    if not np.isfinite(t_map) or lapse >= lapse_limit:
        conditions.append("lapse_at_bound")
    elif t_map < lo_level:
        conditions.append("censored_below")
    elif t_map > hi_level:
        conditions.append("censored_above")
    pairs = separated_peaks(np.asarray(gp.posterior))
    apart = any(climbs_apart(data, gp.priors, gp.grid, gp.bounds, top, other) for top, other in pairs)
    distinct = _distinct_thresholds(gp.modes, high - low, target_kw=target_kw) if target_kw else \
        _distinct_thresholds(gp.modes, high - low)
    if apart or distinct:
        conditions.append("bimodal")
    if _edge_mass(gp.dense_grid, gp.dense_posterior, gp.bounds, gp.names) or gp.cut_axes:
        conditions.append("posterior_at_grid_edge")
    if not np.isfinite(high):
        conditions.append("no_upper_bound")
    return conditions, bool(pairs and not apart)


def _fit_flags(data: np.ndarray, conditions: list[str], joined: bool, level_range: tuple[float, float],
               ci: tuple[float, float]) -> list[str]:
    """Every condition met, then the descriptive flags (joined peaks, all correct, CI beyond the levels)."""
    lo_level, hi_level = level_range
    low, high = ci
    flags = [s for s in STATUSES if s in conditions]
    if joined:
        flags.append("grid_peaks_joined")
    if np.all(data[:, 1] == data[:, 2]):
        flags.append("all_correct")
    if np.isfinite(low) and low < lo_level:
        flags.append("ci_below_range")
    if np.isfinite(high) and high > hi_level:
        flags.append("ci_above_range")
    return flags


def _eta(data: np.ndarray, options: FitOptions, eta_map: float) -> float:
    """The overdispersion reported: the MAP's when eta is free; with eta fixed, its posterior mean under free eta
    (``estimate_eta``) or NaN."""
    if options.fixed_eta is None:
        return eta_map
    if not options.estimate_eta:
        return float("nan")
    free = grid_posterior(data, replace(options, fixed_eta=None, map_refinements=0, posterior_refinements=0))
    return float((free.mesh["eta"] * free.posterior).sum())


def fit_psychometric(data: np.ndarray, options: FitOptions = FitOptions(), source: str = "psychometric data"
                     ) -> PsychometricFit:
    """Fit a cumulative normal to ``data`` (rows ``[level_D, n_correct, n_total]``; yes/no: n_yes for
    n_correct): 2AFC by default, the response kind of ``options`` otherwise (module docstring).

    Follows ``psignifit.psignifit`` step by step (same Configuration, bounds, priors,
    sparse grid -> tightened bounds -> dense grid), refines the posterior grid for the CI and
    zooms into the MAP. Rows with ``n_total == 0`` carry no information and are left out.
    """
    data = validate_blocks(np.asarray(data, float).reshape(-1, 3) if np.size(data) else np.empty((0, 3)), source)
    data = data[data[:, 2] > 0]
    if len(np.unique(data[:, 0])) < 2:
        return _no_fit(data, ("fewer_than_two_levels",), options)
    gp = grid_posterior(data, options)
    target = options.target_p
    target_kw = _target_kwargs(target)
    grid_max = gp.grid_max
    levels = data[:, 0]
    lo_level, hi_level = float(levels.min()), float(levels.max())
    half = (1.0 - options.ci_level) / 2.0
    low, high = weighted_quantiles(gp.t75_D, gp.posterior, (half, 1.0 - half))
    t_map = float(_t75(grid_max, **target_kw))

    width = float(grid_max["width"])
    lapse = float(grid_max["lambda"])
    location = float(grid_max["threshold"])
    guess = float(grid_max["gamma"])
    guess_kw = {} if guess == GUESS_2AFC else {"guess": guess}
    best_pc = predicted_pc(levels, grid_max["threshold"], grid_max["width"], grid_max["lambda"], **guess_kw)
    gof = deviance_test(data[:, 1], data[:, 2], best_pc, options.n_bootstrap, options.seed)

    eta = _eta(data, options, float(grid_max["eta"]))

    # nAFC: no threshold once 1 - lapse <= target_p; yes/no: once the curve is flat or falling (1 - lapse <= guess)
    lapse_limit = 1.0 - (guess if target is None else target)
    if lapse_limit == LAPSE_NO_THRESHOLD and not target_kw:  # 2AFC: the former call
        conditions, joined = _fit_conditions(data, gp, t_map, lapse, (lo_level, hi_level), (low, high))
    else:
        conditions, joined = _fit_conditions(data, gp, t_map, lapse, (lo_level, hi_level), (low, high),
                                             lapse_limit=lapse_limit, target_kw=target_kw)
    status = next((s for s in STATUSES if s in conditions), "ok")
    flags = _fit_flags(data, conditions, joined, (lo_level, hi_level), (low, high))

    threshold = t_map
    bound = float("nan")
    if status == "censored_below":
        threshold, bound = float("nan"), lo_level
    elif status in ("censored_above", "lapse_at_bound"):
        threshold, bound = float("nan"), hi_level
    # psignifit's 'norm' width spans the 5 %-95 % points of the unscaled sigmoid: 2 * 1.645 sd
    sigma = width / WIDTH_PER_SIGMA
    return PsychometricFit(
        status=status, threshold_D=threshold, threshold_ci_low_D=float(low), threshold_ci_high_D=float(high),
        threshold_bound_D=bound, width_D=width, sigma_D=float(sigma), location_D=location, lapse=lapse, eta=eta,
        deviance=gof.deviance, deviance_p=gof.p_value, n_levels=len(data), n_trials=int(data[:, 2].sum()),
        level_min_D=lo_level, level_max_D=hi_level, flags=tuple(flags),
        guess=guess, target_p=guess + (1.0 - guess - lapse) / 2.0 if target is None else target,
    )


def _fit_task(args: tuple[np.ndarray, FitOptions]) -> PsychometricFit:
    return fit_psychometric(*args)


def fit_many(datasets: Sequence[np.ndarray], options: FitOptions = FitOptions(), n_jobs: int = 1) -> list[PsychometricFit]:
    """Fit every dataset; ``n_jobs`` > 1 spreads fits over processes (-1: all cores)."""
    if n_jobs < 0:
        n_jobs = os.cpu_count() or 1
    tasks = [(validate_blocks(d, f"dataset {i}"), options) for i, d in enumerate(datasets)]
    if n_jobs == 1 or len(tasks) < 2:
        return [fit_psychometric(*t) for t in tasks]
    with ProcessPoolExecutor(max_workers=min(n_jobs, len(tasks))) as pool:
        return list(pool.map(_fit_task, tasks, chunksize=max(1, len(tasks) // (4 * n_jobs))))


FIT_COLUMNS = [
    "status", "threshold_D", "threshold_ci_low_D", "threshold_ci_high_D", "threshold_bound_D", "width_D",
    "sigma_D", "location_D", "lapse", "eta", "deviance", "deviance_p", "n_levels", "n_trials", "level_min_D",
    "level_max_D",
]
#: Columns :func:`fit_psychometric_table` adds for options other than the default 2AFC.
KIND_FIT_COLUMNS = ["guess", "target_p"]


def usable_for_analysis(fits: pd.DataFrame) -> tuple[pd.DataFrame, dict[str, int]]:
    """The documented exclusion rule: keep fits whose status is in :data:`USABLE_STATUSES`.

    Censored, lapse-at-bound, bimodal, grid-edge and no-fit thresholds are left out of means,
    ANOVAs and regressions (they are bounds or ambiguous, not numbers). Returns the kept rows
    and ``{status: count}`` of the rows left out.
    """
    if "status" not in fits:
        raise KeyError("fit table lacks a 'status' column; refit with this version of psyop")
    keep = fits["status"].isin(USABLE_STATUSES)
    excluded = fits.loc[~keep, "status"].value_counts().sort_index()
    return fits[keep], {str(k): int(v) for k, v in excluded.items()}


#: Flags of a fit whose 95 % CI is open (an infinite bound) or reaches beyond the tested levels.
OPEN_INTERVAL_FLAGS = ("no_upper_bound", "ci_below_range", "ci_above_range")


def interval_report(fits: pd.DataFrame) -> dict:
    """The fits used as numbers (:data:`USABLE_STATUSES`) whose CI is open or out of range, counted.

    Such a fit's threshold is a point inside the tested levels and enters means, tests and the
    censored-data model as a number; its interval is a posterior extrapolation beyond the levels
    (or unbounded). The group intervals come from the spread over participants, not from each fit's
    interval, so nothing is dropped or substituted: the count and the rule are reported instead.
    Returns ``{"n_used", "n_open_or_out_of_range", "by_flag": {flag: count}, "text"}``; a fit with
    several of the flags counts once in ``n_open_or_out_of_range`` and under each flag.

    Examples
    --------
    >>> fits = pd.DataFrame({"status": ["ok", "no_upper_bound", "censored_below"],
    ...                      "flags": ["ci_below_range", "no_upper_bound", "censored_below;ci_below_range"]})
    >>> r = interval_report(fits)
    >>> r["n_used"], r["n_open_or_out_of_range"], r["by_flag"]
    (2, 2, {'no_upper_bound': 1, 'ci_below_range': 1, 'ci_above_range': 0})
    """
    used = fits[fits["status"].astype(str).isin(USABLE_STATUSES)]
    flags = [set(str(f).split(";")) if isinstance(f, str) else set() for f in used.get("flags", [""] * len(used))]
    for i, status in enumerate(used["status"].astype(str)):
        flags[i].add(status)  # a no_upper_bound status is the open interval whether or not flags repeat it
    by_flag = {flag: sum(flag in f for f in flags) for flag in OPEN_INTERVAL_FLAGS}
    n_open = sum(bool(f & set(OPEN_INTERVAL_FLAGS)) for f in flags)
    counts = ", ".join(f"{k}: {v}" for k, v in by_flag.items() if v) or "none"
    text = (f"{n_open} of {len(used)} fits used as numbers have an open or out-of-range 95 % CI ({counts}): "
            "kept at their threshold (inside the tested levels) in the means, tests and censored-data model; "
            "the group intervals come from the spread over participants, not from these per-fit intervals, "
            "which are extrapolations beyond the tested levels (flagged in the fit table, not used)"
            if n_open else f"all {len(used)} fits used as numbers have a closed 95 % CI inside the tested levels")
    return {"n_used": len(used), "n_open_or_out_of_range": n_open, "by_flag": by_flag, "text": text}


def fit_psychometric_table(
    trials: pd.DataFrame,
    level_column: str = "level_D",
    group_columns: Sequence[str] = ("participant", "back_D"),
    correct_column: str = "correct",
    options: FitOptions = FitOptions(),
    n_jobs: int = 1,
) -> pd.DataFrame:
    """One row per group (e.g. subject x condition) with status, threshold, CI, width, lapse, eta, GOF, flags.

    Trials with a null ``correct`` (no response) are dropped and counted in ``n_missing``; a
    trial with a missing or infinite level raises :class:`InvalidPsychometricData` naming the rows.
    ``flags`` is a ';'-joined string so the table stays CSV-friendly.
    """
    group_columns = list(group_columns)
    missing = [c for c in [level_column, correct_column, *group_columns] if c not in trials]
    if missing:
        raise KeyError(f"trials lack columns {missing}")
    bad_level = ~np.isfinite(pd.to_numeric(trials[level_column], errors="coerce").to_numpy(float))
    if bad_level.any():
        rows = list(trials.index[bad_level][:10])
        raise InvalidPsychometricData(
            f"{int(bad_level.sum())} trial(s) have a missing or non-numeric {level_column!r} (trial table index "
            f"{rows}{' ...' if bad_level.sum() > 10 else ''}); fix or drop them before fitting", "trials")
    keys, datasets, n_missing = [], [], []
    for key, group in trials.groupby(group_columns, sort=True):
        answered = group[group[correct_column].notna()]
        keys.append(key if isinstance(key, tuple) else (key,))
        n_missing.append(len(group) - len(answered))
        datasets.append(aggregate_blocks(answered[level_column].to_numpy(float), answered[correct_column].to_numpy(bool)))
    fits = fit_many(datasets, options, n_jobs)
    columns = FIT_COLUMNS if options.experiment == "nAFC" and options.guess == GUESS_2AFC else \
        FIT_COLUMNS + KIND_FIT_COLUMNS
    rows = []
    for key, fit, miss in zip(keys, fits, n_missing):
        row = dict(zip(group_columns, key))
        row.update({c: getattr(fit, c) for c in columns})
        row["n_missing"] = miss
        row["flags"] = ";".join(fit.flags)
        rows.append(row)
    return pd.DataFrame(rows)
