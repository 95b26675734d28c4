"""k-point rating scales: condition means with t intervals, the repeated-measures ANOVA of participant means,
and a cumulative-link (ordinal) model of the ratings.

Input is a tidy trial table, one row per trial: ``participant``, the condition columns the caller names and
``rating`` (an integer 1..k, k = ``points``).

Means of ratings treat the scale as interval; :func:`ordinal_model` does not: it fits a latent variable
with cut points (statsmodels' ``OrderedModel``), P(rating <= j) = F(cut_j - x'b), F the standard normal
(``link="probit"``) or logistic distribution. A positive coefficient shifts ratings up; under the probit
link it is the shift of the latent mean in units of the latent sd.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from psyop.errors import UserError
from psyop.statistics.anova import AnovaResult
from psyop.statistics.anova import rm_anova as _rm_anova
from psyop.statistics.conditions import condition_of, level_text, numeric_levels, with_condition
from psyop.statistics.signal_detection import check_ci_level, require_columns, t_summary

#: the links :func:`ordinal_model` fits, by their statsmodels ``distr`` names
LINKS = ("probit", "logit")
#: :class:`OrdinalModelResult` flags
FLAG_UNUSED, FLAG_SEPARATION, FLAG_NOT_CONVERGED, FLAG_SE = (
    "unused_categories", "separation", "not_converged", "se_not_finite")


def ratings_of(trials: pd.DataFrame, points: int | None = None) -> np.ndarray:
    """``trials["rating"]`` as integers, checked: no missing value, whole numbers, 1..``points``."""
    values = pd.to_numeric(trials["rating"], errors="coerce")
    if values.isna().any():
        raise UserError(f"column 'rating' has {int(values.isna().sum())} missing or non-numeric value(s): drop "
                        "the unanswered trials first")
    v = values.to_numpy(float)
    if not np.all(v == np.round(v)):
        raise UserError(f"column 'rating' must hold whole scale points; it holds e.g. {v[v != np.round(v)][0]:g}")
    if points is not None and (int(points) != points or points < 2):
        raise UserError(f"points is the number of scale points (an integer >= 2), got {points!r}")
    top = int(points) if points is not None else int(v.max())
    bad = v[(v < 1) | (v > top)]
    if len(bad):
        raise UserError(f"ratings must lie in 1..{top} (points={top}); found {bad[0]:g}: recode the scale to start "
                        "at 1 or pass the right points")
    return v.astype(np.int64)


def participant_means(trials: pd.DataFrame, conditions: Sequence[str] = (), points: int | None = None) -> pd.DataFrame:
    """Mean rating (scale points) and number of trials per participant x condition.

    Examples
    --------
    >>> t = pd.DataFrame({"participant": ["a", "a", "b"], "rating": [1, 4, 3]})
    >>> participant_means(t).to_dict("list")
    {'participant': ['a', 'b'], 'rating': [2.5, 3.0], 'n_trials': [2, 1]}
    """
    keys = ["participant", *conditions]
    require_columns(trials, [*keys, "rating"], "participant_means")
    data = trials[keys].assign(rating=ratings_of(trials, points).astype(float))
    out = data.groupby(keys, observed=True, sort=True, dropna=False)["rating"].agg(["mean", "size"]).reset_index()
    return out.rename(columns={"mean": "rating", "size": "n_trials"})


def condition_means(trials: pd.DataFrame, conditions: Sequence[str] = (), ci_level: float = 0.95,
                    points: int | None = None) -> pd.DataFrame:
    """Per condition, the mean over participants of their mean rating (scale points) with a t interval.

    :func:`psyop.statistics.signal_detection.t_summary`'s columns (``measure`` is 'rating', ``n`` counts
    participants; fewer than 2 are flagged ``n_below_2``) plus ``n_trials``.

    Examples
    --------
    >>> t = pd.DataFrame({"participant": ["a", "a", "b", "b"], "rating": [1, 3, 3, 5]})
    >>> condition_means(t)[["mean", "n", "n_trials"]].to_dict("records")
    [{'mean': 3.0, 'n': 2, 'n_trials': 4}]
    """
    means = participant_means(trials, conditions, points)
    out = t_summary(means, conditions, ["rating"], ci_level)
    if not conditions:
        return out.assign(n_trials=int(means["n_trials"].sum()))
    n_trials = means.groupby(list(conditions), observed=True, dropna=False)["n_trials"].sum().reset_index()
    return out.merge(n_trials, on=list(conditions), how="left")


def rm_anova(trials: pd.DataFrame, conditions: Sequence[str], points: int | None = None) -> AnovaResult:
    """Repeated-measures ANOVA (:func:`psyop.statistics.anova.rm_anova`, Greenhouse-Geisser) of the
    participants' mean ratings over one or two condition factors, each with at least 2 levels."""
    conditions = list(conditions)
    if not 1 <= len(conditions) <= 2:
        raise UserError(f"rm_anova of ratings takes one or two condition factors, got {len(conditions)} "
                        f"({', '.join(conditions) or 'none'}); cross several into one column first")
    means = participant_means(trials, conditions, points)
    single = [c for c in conditions if means[c].nunique() < 2]
    if single:
        raise UserError(f"condition factor(s) {', '.join(map(repr, single))} have a single level: there is "
                        "nothing to compare; leave them out of the conditions")
    return _rm_anova(means, "rating", conditions)


@dataclass(frozen=True)
class OrdinalModelResult:
    """A cumulative-link model of ratings over conditions (:func:`ordinal_model`).

    ``coefficients``: term, estimate, se, z, p, ci_low, ci_high (Wald, normal) for each non-reference
    condition level ('condition=level', the shift of the latent mean from the reference) and, with
    participant offsets, each non-first participant. ``thresholds``: the cut points between consecutive
    *used* categories ('2|3'), with delta-method se and Wald CIs, on the latent scale (reference condition).
    ``flags`` (';'-joined) and ``flag_text`` say what makes a number unreliable."""

    coefficients: pd.DataFrame
    thresholds: pd.DataFrame
    log_likelihood: float
    converged: bool
    link: str
    condition: str
    reference: object
    categories_used: tuple[int, ...]
    n_trials: int
    n_participants: int
    ci_level: float
    flags: str = ""
    flag_text: str = ""


def _sorted_levels(values: pd.Series) -> list:
    levels = list(pd.unique(values))
    if numeric_levels(pd.Series(levels)):
        return sorted(levels, key=float)
    return sorted(levels, key=str)


def _design(data: pd.DataFrame, condition: str, reference: object, participant_offsets: bool
            ) -> tuple[pd.DataFrame, list]:
    levels = _sorted_levels(data[condition])
    if len(levels) < 2:
        raise UserError(f"ordinal_model compares conditions, but {condition!r} has a single level "
                        f"({level_text(levels[0])}); use condition_means for one condition")
    ref = levels[0] if reference is None else reference
    if ref not in levels:
        raise UserError(f"reference {reference!r} is not a level of {condition!r} "
                        f"({', '.join(map(level_text, levels))})")
    columns = {f"{condition}={level_text(lv)}": (data[condition] == lv).astype(float) for lv in levels if lv != ref}
    if participant_offsets:
        people = _sorted_levels(data["participant"])
        columns |= {f"participant={p}": (data["participant"] == p).astype(float) for p in people[1:]}
    return pd.DataFrame(columns, index=data.index), [ref, *[lv for lv in levels if lv != ref]]


def _separated_levels(data: pd.DataFrame, condition: str, y: np.ndarray) -> list[str]:
    """Condition levels whose every rating is the lowest or every rating the highest used category:
    their coefficient runs off to infinity."""
    lo, hi = y.min(), y.max()
    frame = pd.DataFrame({"c": data[condition].to_numpy(), "y": y})
    out = []
    for lv, g in frame.groupby("c", sort=False):
        if (g["y"] == lo).all() or (g["y"] == hi).all():
            out.append(level_text(lv))
    return out


def _wald_table(names: Sequence[str], est: np.ndarray, se: np.ndarray, level: float, label: str) -> pd.DataFrame:
    zq = stats.norm.ppf(0.5 + level / 2.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        z = est / se
    return pd.DataFrame({label: list(names), "estimate": est, "se": se, "z": z, "p": 2 * stats.norm.sf(np.abs(z)),
                         "ci_low": est - zq * se, "ci_high": est + zq * se})


def _thresholds(raw: np.ndarray, cov: np.ndarray, used: Sequence[int], level: float) -> pd.DataFrame:
    """Cut points from statsmodels' parametrisation (first cut, then log increments), with delta-method se."""
    k = len(raw)
    cuts = np.cumsum(np.r_[raw[0], np.exp(raw[1:])])
    jac = np.zeros((k, k))
    for i in range(k):
        jac[i, 0] = 1.0
        jac[i, 1:i + 1] = np.exp(raw[1:i + 1])
    with np.errstate(invalid="ignore"):
        se = np.sqrt(np.diag(jac @ cov @ jac.T))
    names = [f"{a}|{b}" for a, b in zip(used[:-1], used[1:])]
    return _wald_table(names, cuts, se, level, "cut")


def _fit(y: np.ndarray, exog: pd.DataFrame, link: str):
    from statsmodels.miscmodels.ordinal_model import OrderedModel

    model = OrderedModel(y, exog, distr=link)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # convergence and Hessian problems are judged below, from the fit
        return model.fit(method="bfgs", disp=False, maxiter=2000)


def _flag_texts(unused: list[int], separated: list[str], converged: bool, se_ok: bool) -> tuple[list, list]:
    flags, texts = [], []
    if unused:
        flags.append(FLAG_UNUSED)
        texts.append(f"categories {', '.join(map(str, unused))} never used: their cut points are not estimated "
                     "(the thresholds join the used neighbours)")
    if separated:
        flags.append(FLAG_SEPARATION)
        texts.append(f"every rating in {', '.join(separated)} is an extreme category: its coefficient is unbounded "
                     "(the estimate is where the optimizer stopped)")
    if not converged:
        flags.append(FLAG_NOT_CONVERGED)
        texts.append("the optimizer did not converge")
    if not se_ok:
        flags.append(FLAG_SE)
        texts.append("some standard errors are not finite (the Hessian is singular)")
    return flags, texts


def ordinal_model(trials: pd.DataFrame, conditions: Sequence[str], points: int, link: str = "probit",
                  ci_level: float = 0.95, reference: object = None,
                  participant_offsets: bool = False) -> OrdinalModelResult:
    """Cumulative-link model of ``rating`` on the condition (dummy coded against ``reference``, by default
    the first level), fitted by maximum likelihood with statsmodels' ``OrderedModel``.

    Several condition factors are crossed into one condition (their cells, as
    :mod:`psyop.statistics.conditions` does). Trials are modelled as independent; ``participant_offsets``
    adds a fixed latent shift per participant (compare conditions within participants). A single condition
    level, no condition factor, fewer than 2 used categories or an unknown link raise :class:`UserError`;
    unused categories, separation, non-convergence and non-finite SEs are flagged in the result.
    """
    if link not in LINKS:
        raise UserError(f"link must be one of {', '.join(LINKS)}, got {link!r}")
    if not conditions:
        raise UserError("ordinal_model needs at least one condition column to compare; use condition_means")
    level = check_ci_level(ci_level)
    require_columns(trials, ["participant", *conditions, "rating"], "ordinal_model")
    y = ratings_of(trials, points)
    used = sorted(int(v) for v in np.unique(y))
    if len(used) < 2:
        raise UserError(f"every rating is {used[0]}: an ordinal model needs at least two categories used")
    condition = condition_of(conditions)
    data = with_condition(trials, conditions)
    exog, order = _design(data, condition, reference, participant_offsets)
    res = _fit(y, exog, link)
    params, cov = np.asarray(res.params, float), np.asarray(res.cov_params(), float)
    se = np.sqrt(np.clip(np.diag(cov), 0, None)) if np.all(np.isfinite(cov)) else np.full(len(params), np.nan)
    p = exog.shape[1]
    coefficients = _wald_table(list(exog.columns), params[:p], se[:p], level, "term")
    thresholds = _thresholds(params[p:], cov[p:, p:], used, level)
    converged = bool(res.mle_retvals.get("converged", False))
    se_ok = bool(np.all(np.isfinite(se)) and np.all(np.isfinite(thresholds["se"])))
    flags, texts = _flag_texts([k for k in range(1, int(points) + 1) if k not in used],
                               _separated_levels(data, condition, y), converged, se_ok)
    return OrdinalModelResult(coefficients=coefficients, thresholds=thresholds, log_likelihood=float(res.llf),
                              converged=converged, link=link, condition=condition, reference=order[0],
                              categories_used=tuple(used), n_trials=len(y),
                              n_participants=int(trials["participant"].nunique()), ci_level=level,
                              flags=";".join(flags), flag_text="; ".join(texts))


__all__ = ["LINKS", "OrdinalModelResult", "ratings_of", "participant_means", "condition_means", "rm_anova",
           "ordinal_model"]
