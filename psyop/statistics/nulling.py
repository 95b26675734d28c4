"""A nulling task's point of subjective stability (PSS) with its credible interval (NC calibration).

Data: rows ``[level, n_against, n_total]`` (level: the signed NC a trial was rendered with, mm). The model
is psignifit 4's cumulative normal with equal asymptotes, p(against) = lambda + (1 - 2 lambda) *
Phi((x - pss) / sigma), fitted by psignifit itself (``experiment_type="equal asymptote"``: a yes/no
judgement whose guess and lapse rates are one lapse; eta fixed to 0, as psyop.statistics.psychometric fixes
it for its 2AFC thresholds). The 2AFC fit of psyop.statistics.psychometric cannot be used: its guess rate is
fixed at 0.5 and its threshold is the 75 %-correct point, neither of which a with/against judgement has.
psignifit's threshold parameter at 50 % (``thresh_PC=0.5``) is the PSS, its 95 % credible interval
psignifit's.

Status (one per fit, the first that applies): ``no_fit`` (fewer than two levels: all NaN),
``censored_below`` / ``censored_above`` (the PSS lies beyond the lowest / highest level rendered: ``pss_mm``
NaN, ``pss_bound_mm`` that level), ``ok``. ``flags`` adds ``one_answer`` (every trial got the same answer),
``ci_below_range`` / ``ci_above_range`` (an interval bound beyond the levels rendered).
"""

from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

from psyop.statistics.psychometric import WIDTH_PER_SIGMA, aggregate_blocks, validate_blocks

CI_LEVEL = 0.95
STATUSES = ("no_fit", "censored_below", "censored_above", "ok")


@dataclass(frozen=True)
class NullingFit:
    """One participant's PSS (mm of rendered NC), NaN where the status allows no number."""

    status: str
    pss_mm: float
    pss_ci_low_mm: float
    pss_ci_high_mm: float
    #: censored fits: the level the PSS lies beyond (NaN otherwise)
    pss_bound_mm: float
    sigma_mm: float  # sd of the cumulative normal
    lapse: float
    n_levels: int
    n_trials: int
    level_min_mm: float
    level_max_mm: float
    flags: tuple[str, ...]

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def as_row(self) -> dict[str, object]:
        row = asdict(self)
        row["flags"] = ",".join(self.flags)
        return row


def fit_nulling(data: np.ndarray, source: str = "nulling data") -> NullingFit:
    """The PSS of rows ``[level_mm, n_against, n_total]`` (psignifit, equal asymptotes; module docstring).

    Examples
    --------
    >>> import numpy as np
    >>> levels = np.array([-8.0, -4, 0, 4, 8, 12, 16, 20])
    >>> against = np.array([0, 1, 1, 4, 11, 16, 19, 20])
    >>> fit = fit_nulling(np.c_[levels, against, np.full(8, 20)])
    >>> fit.status, 4 < fit.pss_mm < 10, fit.pss_ci_low_mm < fit.pss_mm < fit.pss_ci_high_mm
    ('ok', True, True)
    """
    import psignifit

    data = validate_blocks(np.asarray(data, float).reshape(-1, 3) if np.size(data) else np.empty((0, 3)), source)
    data = data[data[:, 2] > 0]
    levels = data[:, 0]
    n_trials = int(data[:, 2].sum())
    if len(np.unique(levels)) < 2:
        nan = float("nan")
        return NullingFit("no_fit", nan, nan, nan, nan, nan, nan, len(data), n_trials, nan, nan, ("no_fit",))
    lo, hi = float(levels.min()), float(levels.max())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = psignifit.psignifit(data, experiment_type="equal asymptote", sigmoid="norm", verbose=False,
                                     fixed_parameters={"eta": 0.0}, thresh_PC=0.5, confP=(CI_LEVEL,))
    estimate = result.parameter_estimate
    low, high = (float(v) for v in result.confidence_intervals["threshold"][str(CI_LEVEL)])
    pss = float(estimate["threshold"])
    # psignifit's 'norm' width spans the 5 %-95 % points of the unscaled sigmoid: 2 * 1.645 sd
    sigma = float(estimate["width"]) / WIDTH_PER_SIGMA
    conditions = []
    if pss < lo:
        conditions.append("censored_below")
    elif pss > hi:
        conditions.append("censored_above")
    status = next((s for s in STATUSES if s in conditions), "ok")
    flags = list(conditions)
    if np.all(data[:, 1] == data[:, 2]) or np.all(data[:, 1] == 0):
        flags.append("one_answer")
    if low < lo:
        flags.append("ci_below_range")
    if high > hi:
        flags.append("ci_above_range")
    bound = float("nan")
    if status == "censored_below":
        pss, bound = float("nan"), lo
    elif status == "censored_above":
        pss, bound = float("nan"), hi
    return NullingFit(status, pss, low, high, bound, sigma, float(estimate["lambda"]), len(data), n_trials, lo, hi,
                      tuple(flags))


def nulling_blocks(trials: pd.DataFrame, level_column: str = "rendered_nc_mm") -> np.ndarray:
    """Rows ``[level, n_against, n_total]`` of one participant's trials (``response`` 'with' / 'against')."""
    levels = trials[level_column].to_numpy(dtype=float)
    against = (trials["response"].astype(str) == "against").to_numpy()
    return aggregate_blocks(levels, against)


def pss_text(fit: NullingFit) -> str:
    """The PSS as a reader should see it: a number with its interval, or a censored bound."""
    if fit.status == "ok":
        return f"{fit.pss_mm:.2f} mm [{fit.pss_ci_low_mm:.2f}, {fit.pss_ci_high_mm:.2f}]"
    if fit.status == "censored_below":
        return f"< {fit.pss_bound_mm:g} mm (below the levels rendered)"
    if fit.status == "censored_above":
        return f"> {fit.pss_bound_mm:g} mm (above the levels rendered)"
    return "no fit (fewer than two levels)"
