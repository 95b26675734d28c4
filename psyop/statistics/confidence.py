"""Confidence ratings after a choice (``response: confidence:``, psyop.protocol.kinds.confidence): the mean
confidence per condition for correct and incorrect answers, and the type-2 ROC area per participant.

- :func:`confidence_means`: each participant's mean confidence per condition and correctness, then the mean of
  those over participants with a t interval (:func:`psyop.statistics.signal_detection.t_summary`, its flags: a cell
  with one participant has no interval, ``n_below_2``). A condition where no participant answered wrongly has no
  ``correct = False`` row.
- :func:`type2_auroc`: how well confidence tells a participant's correct answers from the wrong ones: the area
  under the type-2 ROC, A = P(c_correct > c_wrong) + P(tie) / 2 over all pairs of a correct and a wrong trial (the
  Mann-Whitney U over n_correct * n_wrong), with DeLong et al.'s (1988) variance from the placement values (exact
  with tied ratings) and a normal interval A -/+ z * SE, clipped to [0, 1] (flag ``ci_clipped``). It pools the
  participant's trials over conditions. No correct or no wrong trial: A is undefined (NaN, flag ``no_correct`` /
  ``no_wrong``); SE 0 (every pair ordered alike): a zero-width interval (flag ``zero_se``).
- :func:`auroc_summary`: the participants' areas' mean with a t interval (clipped to [0, 1], flag ``ci_clipped``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd
from scipy import stats

from psyop.statistics.signal_detection import t_summary

#: the trial-log column of the rating (1..k; null: not answered) and its scale's points (schedule)
CONFIDENCE, POINTS = "confidence", "confidence_points"


def has_confidence(trials: pd.DataFrame) -> bool:
    """Whether ``trials`` hold confidence ratings (the column, with at least one answer)."""
    return CONFIDENCE in trials and bool(pd.to_numeric(trials[CONFIDENCE], errors="coerce").notna().any())


def _rated(trials: pd.DataFrame) -> pd.DataFrame:
    """The trials with both a rating and a correctness (confidence as float, correct as bool)."""
    confidence = pd.to_numeric(trials[CONFIDENCE], errors="coerce")
    keep = confidence.notna() & trials["correct"].notna()
    out = trials.loc[keep].copy()
    out[CONFIDENCE] = confidence[keep].astype(float)
    out["correct"] = out["correct"].astype(bool)
    return out


def confidence_means(trials: pd.DataFrame, conditions: Sequence[str], ci_level: float = 0.95) -> pd.DataFrame:
    """Mean confidence per condition and correctness (see the module docstring): the condition columns,
    ``correct``, then t_summary's columns (``n`` participants, ``mean``, ``ci_low``, ``ci_high``, ``flags``, ...)."""
    rated = _rated(trials)
    keys = ["participant", *conditions, "correct"]
    per = rated.groupby(keys, observed=True)[CONFIDENCE].mean().reset_index()
    return t_summary(per, [*conditions, "correct"], [CONFIDENCE], ci_level)


@dataclass(frozen=True)
class Type2Auroc:
    """One participant's type-2 ROC area (see the module docstring)."""

    auroc: float
    se: float
    ci_low: float
    ci_high: float
    n_correct: int
    n_wrong: int
    flags: str


def type2_auroc(confidence: np.ndarray, correct: np.ndarray, ci_level: float = 0.95) -> Type2Auroc:
    """The type-2 ROC area of ratings ``confidence`` against ``correct`` (booleans), with DeLong's SE.

    Examples
    --------
    >>> r = type2_auroc(np.array([4, 3, 3, 1, 2, 1]), np.array([True, True, False, False, True, False]))
    >>> round(r.auroc, 4), r.n_correct, r.n_wrong, r.flags
    (0.8333, 3, 3, 'ci_clipped')
    """
    c = np.asarray(confidence, dtype=float)
    ok = np.asarray(correct, dtype=bool)
    right, wrong = c[ok], c[~ok]
    if right.size == 0 or wrong.size == 0:
        flag = "no_correct" if right.size == 0 else "no_wrong"
        return Type2Auroc(np.nan, np.nan, np.nan, np.nan, int(right.size), int(wrong.size), flag)
    psi = (right[:, None] > wrong[None, :]) + 0.5 * (right[:, None] == wrong[None, :])
    auroc = float(psi.mean())
    v10, v01 = psi.mean(axis=1), psi.mean(axis=0)
    var = (v10.var(ddof=1) / right.size if right.size > 1 else 0.0) + \
        (v01.var(ddof=1) / wrong.size if wrong.size > 1 else 0.0)
    se = float(np.sqrt(var))
    z = float(stats.norm.ppf(0.5 + ci_level / 2.0))
    low, high = auroc - z * se, auroc + z * se
    flags = [name for name, on in (("zero_se", se == 0.0), ("ci_clipped", low < 0.0 or high > 1.0)) if on]
    return Type2Auroc(auroc, se, max(low, 0.0), min(high, 1.0), int(right.size), int(wrong.size), ";".join(flags))


def auroc_by_participant(trials: pd.DataFrame, ci_level: float = 0.95) -> pd.DataFrame:
    """One row per participant: ``participant`` and :class:`Type2Auroc`'s fields, over all their rated trials."""
    rows = []
    for participant, own in _rated(trials).groupby("participant", observed=True):
        result = type2_auroc(own[CONFIDENCE].to_numpy(), own["correct"].to_numpy(), ci_level)
        rows.append({"participant": participant, **asdict(result)})
    columns = ["participant", *Type2Auroc.__dataclass_fields__]
    return pd.DataFrame(rows, columns=columns)


def auroc_summary(per_participant: pd.DataFrame, ci_level: float = 0.95) -> pd.DataFrame:
    """The participants' type-2 ROC areas: their mean with a t interval (one row; t_summary's columns), the
    interval clipped to [0, 1] where it reaches past an area's range (flag ``ci_clipped``)."""
    out = t_summary(per_participant, [], ["auroc"], ci_level)
    beyond = (out["ci_low"] < 0.0) | (out["ci_high"] > 1.0)
    out["ci_low"], out["ci_high"] = out["ci_low"].clip(lower=0.0), out["ci_high"].clip(upper=1.0)
    out.loc[beyond, "flags"] = [";".join(f for f in (flags, "ci_clipped") if f) for flags in out.loc[beyond, "flags"]]
    return out
