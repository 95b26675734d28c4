"""nAFC and yes/no psychometric functions with psignifit 4.3 (cumulative normal on linear diopters).

The default (``FitOptions()``) is 2AFC: guess rate fixed at 0.5, threshold at 75 % correct.
Other response kinds (:class:`FitOptions` ``experiment`` and ``guess``; section "Response kinds"
below) run the same pipeline with psignifit's grid for their guess rate.

Why not simply ``psignifit.psignifit``: its last step refines the MAP with a Nelder-Mead
search whose objective calls ``scipy.stats.norm.ppf`` on scalars; that step is most of a
~1-2 s fit here, while the grid posterior (priors, bounds, credible intervals) costs tens
of ms. psyop runs psignifit's own pipeline (its Configuration, parameter bounds, default
priors, sparse grid -> tightened bounds -> dense grid) in its posterior-grid engine,
:mod:`psyop.statistics.psignifit_grid` (the model in :mod:`~psyop.statistics.psignifit_posterior`,
the modes in :mod:`~psyop.statistics.posterior_modes`; psignifit's private functions only through
:mod:`~psyop.statistics.psignifit_private`), then

- **moves a grid edge that cuts the posterior** out to the mass (:func:`refine_posterior`,
  :data:`CUT_MASS`): with thousands of trials per level the bounds psignifit tightens on its
  sparse grid can exclude the mode, and a CI read inside them misses;
- **refines the posterior grid** around the posterior mass (:func:`refine_posterior`): the
  dense grid spans the tightened prior bounds, so with many trials per level the whole
  posterior falls between two grid points and a CI read off that grid collapses to the grid
  step. The refined grid spans the mass at the same number of points, repeated until each
  axis's central 95 % spans at least :data:`MIN_CI_POINTS` points;
- **zooms into the posterior mode** with vectorised grids (:func:`~psyop.statistics.posterior_modes._refine_map`) instead of
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

import os
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd
from scipy import special

from psyop.errors import UserError
from psyop.statistics.goodness import deviance_test
from psyop.statistics.posterior_modes import _distinct_thresholds, climbs_apart, is_bimodal, separated_peaks
from psyop.statistics.psignifit_grid import (
    CUT_MASS, EDGE_MASS, MAX_GRID_MOVES, MIN_CI_POINTS, PSIGNIFIT_DEFAULT_GRID, REFINE_TAIL, GridPosterior,
    GridRequest, GridSpec, _edge_mass, grid_cuts_posterior, posterior_on_grid, refine_posterior,
)
from psyop.statistics.psignifit_posterior import (
    TARGET_PC, WIDTH_PER_SIGMA, _norm_standard_parameters, _t75, _target_kwargs, log_posterior_2afc, posterior_2afc,
    tabulate_priors,
)

__all__ = [
    "CUT_MASS", "EDGE_MASS", "EXPERIMENTS", "FIT_COLUMNS", "GUESS_2AFC", "KIND_FIT_COLUMNS", "LAPSE_NO_THRESHOLD",
    "MAX_GRID_MOVES", "MIN_CI_POINTS", "NAFC_CHOICES", "OPEN_INTERVAL_FLAGS", "PSIGNIFIT_DEFAULT_GRID",
    "REFINE_TAIL", "STATUSES", "TARGET_PC", "USABLE_STATUSES", "WIDTH_PER_SIGMA", "FitOptions", "GridPosterior",
    "GridSpec", "InvalidFitOptions", "InvalidPsychometricData", "PsychometricFit", "aggregate_blocks", "climbs_apart",
    "fit_many", "fit_psychometric", "fit_psychometric_table", "grid_cuts_posterior", "grid_posterior",
    "interval_report", "is_bimodal", "log_posterior_2afc", "nafc_options", "posterior_2afc", "predicted_pc",
    "refine_posterior", "separated_peaks", "tabulate_priors", "threshold_text", "usable_for_analysis",
    "validate_blocks", "weighted_quantiles", "yes_no_options",
]

GUESS_2AFC = 0.5
#: Response kinds (:class:`FitOptions` ``experiment``) and the nAFC choices allowed.
EXPERIMENTS = ("nAFC", "yes/no")
NAFC_CHOICES = range(2, 9)
#: A 2AFC curve with lapse >= this never reaches 75 % correct.
LAPSE_NO_THRESHOLD = 0.25

STATUSES = ("no_fit", "lapse_at_bound", "censored_below", "censored_above", "bimodal",
            "posterior_at_grid_edge", "no_upper_bound", "ok")
#: Statuses whose ``threshold_D`` is a point estimate inside the tested range that analyses use.
USABLE_STATUSES = ("ok", "no_upper_bound")


class InvalidPsychometricData(UserError):
    """Rows of ``[level, n_correct, n_total]`` that cannot be fitted, named by row."""


class InvalidFitOptions(UserError):
    """A :class:`FitOptions` that names no fit: an unknown response kind or a guess rate it cannot have."""


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
    """The posterior grid of ``data`` under ``options`` (:func:`psyop.statistics.psignifit_grid.posterior_on_grid`):
    psignifit's pipeline up to the dense-grid posterior, then the refined posterior and MAP."""
    request = GridRequest(
        grid=options.grid, fixed=_fixed_parameters(options), experiment=_psignifit_experiment(options),
        ci_level=options.ci_level, target_p=options.target_p, map_refinements=options.map_refinements,
        posterior_refinements=options.posterior_refinements)
    return posterior_on_grid(data, request)


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
