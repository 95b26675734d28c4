"""Equal-variance signal detection for yes/no tasks: hit and false-alarm rates, d' and c per participant
and condition, and their means across participants with t confidence intervals.

Input is a tidy trial table, one row per trial: ``participant``, the condition columns the caller names
(possibly none), ``signal`` (bool: a signal trial) and ``answer_yes`` (bool: the participant said "yes").

Rates of 0 or 1 make z infinite. psyop corrects **every** participant x condition table with the
log-linear rule (Hautus 1995, Behav. Res. Methods 27:46): 0.5 is added to the hits and to the false
alarms and 1 to the numbers of signal and of noise trials, whether or not a rate is 0 or 1
(:data:`CORRECTION`). Hautus recommends applying it to all cells: correcting only the extreme ones makes
d' jump between a participant with 199/200 and one with 200/200 hits, and the bias it adds is small
(its expected shift of d' is -0.002 at 200 + 200 trials, d' = 1.5, c = 0.2). ``corrected`` says the
rule was applied (always, by this choice), ``correction`` names it, and ``extreme_rate`` marks the rows
whose raw hit or false-alarm rate was 0 or 1 (their d' rests on the correction more than on the data).

The module also holds :func:`t_summary`, the per-condition mean across participants with a t interval
that :mod:`psyop.statistics.ratings` and :mod:`psyop.statistics.adjustment` share.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
from scipy import stats

from psyop.errors import UserError

#: the rate correction applied to every participant x condition: log-linear (Hautus 1995), all cells
CORRECTION = "loglinear_all_cells"
#: what the log-linear rule adds to the hits and to the false alarms ...
LOGLINEAR_ADD_COUNT = 0.5
#: ... and to the numbers of signal and of noise trials
LOGLINEAR_ADD_TRIALS = 1.0

RATE_COLUMNS = [
    "n_signal", "n_noise", "hits", "false_alarms", "hit_rate", "fa_rate", "hit_rate_corrected",
    "fa_rate_corrected", "d_prime", "criterion", "extreme_rate", "corrected", "correction",
]
SUMMARY_COLUMNS = ["measure", "n", "mean", "sd", "se", "ci_low", "ci_high", "ci_level", "n_excluded", "flags"]
#: the t-summary flags: fewer than 2 finite values (sd and CI NaN), all values equal (a zero-width CI),
#: non-finite values left out of n
FLAG_N_BELOW_2, FLAG_ZERO_SD, FLAG_EXCLUDED = "n_below_2", "zero_sd", "excluded_nonfinite"


def require_columns(table: pd.DataFrame, columns: Sequence[str], what: str) -> None:
    """Raise :class:`UserError` naming the columns ``what`` needs that ``table`` lacks."""
    missing = [c for c in columns if c not in table.columns]
    if missing:
        raise UserError(f"{what} needs the column(s) {', '.join(map(repr, missing))}; the table has "
                        f"{', '.join(map(repr, map(str, table.columns))) or 'no columns'}: rename or add them")
    if table.empty:
        raise UserError(f"{what} got an empty table: pass at least one trial")


def cell_name(participant: object, conditions: Sequence[str], values: Sequence[object]) -> str:
    """How an error message names one participant x condition.

    Examples
    --------
    >>> cell_name("p1", ["mode"], ["ocular"]), cell_name("p1", [], [])
    ("participant 'p1', mode='ocular'", "participant 'p1' (no condition columns)")
    """
    where = ", ".join(f"{c}={v!r}" for c, v in zip(conditions, values)) or "(no condition columns)"
    return f"participant {participant!r}{', ' if conditions else ' '}{where}"


def boolean_column(trials: pd.DataFrame, column: str) -> np.ndarray:
    """``trials[column]`` as bool: True/False or 0/1 without missing values, else a :class:`UserError`."""
    values = trials[column]
    if values.isna().any():
        raise UserError(f"column {column!r} has {int(values.isna().sum())} missing value(s): drop the trials "
                        "without an answer (or a stimulus) before computing rates")
    if values.dtype == bool:
        return values.to_numpy(bool)
    numeric = pd.to_numeric(values, errors="coerce")
    if numeric.isna().any() or not numeric.isin([0, 1]).all():
        odd = sorted(set(map(str, values[~numeric.isin([0, 1]) | numeric.isna()].unique())))[:5]
        raise UserError(f"column {column!r} must be True/False (or 1/0); it holds {', '.join(odd)}")
    return numeric.to_numpy(float).astype(bool)


def _check_counts(table: pd.DataFrame, conditions: Sequence[str]) -> None:
    for column, kind in (("n_signal", "signal"), ("n_noise", "noise")):
        empty = table[table[column] == 0]
        if len(empty):
            cells = "; ".join(cell_name(r["participant"], conditions, [r[c] for c in conditions])
                              for _, r in empty.head(5).iterrows())
            raise UserError(f"no {kind} trials for {cells}{' and others' if len(empty) > 5 else ''}: d' needs "
                            f"both signal and noise trials in every participant x condition; drop the cell or "
                            f"fix the 'signal' column")


def rates(trials: pd.DataFrame, conditions: Sequence[str] = ()) -> pd.DataFrame:
    """Hit and false-alarm rates, d' and criterion c per participant x condition.

    Columns: ``participant``, the condition columns, then :data:`RATE_COLUMNS`: trial counts
    (``n_signal``, ``n_noise``), ``hits`` and ``false_alarms`` (counts), the raw rates ``hit_rate``
    = hits / n_signal and ``fa_rate`` = false_alarms / n_noise, the log-linear corrected rates d' and c
    are computed from (:data:`CORRECTION`, in the module docstring), ``d_prime`` = z(H) - z(F) and
    ``criterion`` c = -(z(H) + z(F)) / 2 (both in units of the noise sd), ``extreme_rate`` (a raw rate
    of 0 or 1), ``corrected`` (True: the rule was applied) and ``correction`` (its name).

    A participant x condition without signal or without noise trials raises :class:`UserError` naming it.

    Examples
    --------
    >>> t = pd.DataFrame({"participant": "p1", "signal": [True, True, False, False],
    ...                   "answer_yes": [True, False, False, False]})
    >>> r = rates(t)
    >>> float(r["hit_rate"].iloc[0]), float(r["fa_rate"].iloc[0]), round(float(r["d_prime"].iloc[0]), 3)
    (0.5, 0.0, 0.967)
    """
    conditions = list(conditions)
    keys = ["participant", *conditions]
    require_columns(trials, [*keys, "signal", "answer_yes"], "rates")
    signal, yes = boolean_column(trials, "signal"), boolean_column(trials, "answer_yes")
    counts = trials[keys].assign(n_signal=signal.astype(np.int64), n_noise=(~signal).astype(np.int64),
                                 hits=(signal & yes).astype(np.int64), false_alarms=(~signal & yes).astype(np.int64))
    table = counts.groupby(keys, observed=True, sort=True, dropna=False).sum().reset_index()
    _check_counts(table, conditions)
    n_s, n_n = table["n_signal"].to_numpy(float), table["n_noise"].to_numpy(float)
    hits, fas = table["hits"].to_numpy(float), table["false_alarms"].to_numpy(float)
    table["hit_rate"], table["fa_rate"] = hits / n_s, fas / n_n
    h = (hits + LOGLINEAR_ADD_COUNT) / (n_s + LOGLINEAR_ADD_TRIALS)
    f = (fas + LOGLINEAR_ADD_COUNT) / (n_n + LOGLINEAR_ADD_TRIALS)
    z_h, z_f = stats.norm.ppf(h), stats.norm.ppf(f)
    table["hit_rate_corrected"], table["fa_rate_corrected"] = h, f
    table["d_prime"], table["criterion"] = z_h - z_f, -(z_h + z_f) / 2.0
    table["extreme_rate"] = (hits == 0) | (hits == n_s) | (fas == 0) | (fas == n_n)
    table["corrected"], table["correction"] = True, CORRECTION
    return table[[*keys, *RATE_COLUMNS]]


def check_ci_level(ci_level: float) -> float:
    """``ci_level`` if it lies strictly between 0 and 1, else a :class:`UserError`."""
    if not 0.0 < float(ci_level) < 1.0:
        raise UserError(f"ci_level must lie between 0 and 1 (e.g. 0.95), got {ci_level!r}")
    return float(ci_level)


def _summary_flags(n: np.ndarray, sd: np.ndarray, excluded: np.ndarray) -> list[str]:
    flags = []
    for n_i, sd_i, ex_i in zip(n, sd, excluded):
        f = [FLAG_N_BELOW_2] if n_i < 2 else [FLAG_ZERO_SD] if sd_i == 0 else []
        flags.append(";".join(f + ([FLAG_EXCLUDED] if ex_i else [])))
    return flags


def t_summary(table: pd.DataFrame, conditions: Sequence[str], measures: Sequence[str],
              ci_level: float = 0.95) -> pd.DataFrame:
    """Per condition and measure: the mean of the (participant) values with a t confidence interval.

    One row per condition and measure (in the order given): the condition columns, then
    :data:`SUMMARY_COLUMNS`: ``n`` finite values, ``mean``, ``sd`` (ddof 1), ``se`` = sd / sqrt(n),
    ``ci_low`` and ``ci_high`` = mean -/+ t(1 - (1 - ci_level) / 2, n - 1) * se, ``ci_level``,
    ``n_excluded`` (non-finite values left out) and ``flags`` (';'-joined: :data:`FLAG_N_BELOW_2` with
    sd, se and CI NaN; :data:`FLAG_ZERO_SD`, a zero-width CI; :data:`FLAG_EXCLUDED`).

    Examples
    --------
    >>> s = t_summary(pd.DataFrame({"x": [1.0, 2.0, 3.0]}), [], ["x"])
    >>> float(s["mean"].iloc[0]), round(float(s["ci_high"].iloc[0]), 3), s["flags"].iloc[0]
    (2.0, 4.484, '')
    """
    conditions, measures = list(conditions), list(measures)
    require_columns(table, [*conditions, *measures], "t_summary")
    level = check_ci_level(ci_level)
    long = table.melt(id_vars=conditions, value_vars=measures, var_name="measure", value_name="value")
    long["value"] = pd.to_numeric(long["value"], errors="coerce").astype(float).where(
        lambda v: np.isfinite(v))
    long["measure"] = pd.Categorical(long["measure"], categories=measures)
    out = (long.groupby([*conditions, "measure"], observed=True, sort=True, dropna=False)["value"]
           .agg(n="count", mean="mean", sd="std", size="size").reset_index())
    n = out["n"].to_numpy(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        se = np.where(n >= 2, out["sd"].to_numpy(float) / np.sqrt(n), np.nan)
        half = stats.t.ppf(0.5 + level / 2.0, np.where(n >= 2, n - 1, np.nan)) * se
    out["sd"] = np.where(n >= 2, out["sd"], np.nan)
    out["se"], out["ci_low"], out["ci_high"] = se, out["mean"] - half, out["mean"] + half
    out["ci_level"], out["n_excluded"] = level, out["size"] - out["n"]
    out["flags"] = _summary_flags(n, out["sd"].to_numpy(float), out["n_excluded"].to_numpy() > 0)
    out["measure"] = out["measure"].astype(str)
    return out[[*conditions, *SUMMARY_COLUMNS]]


def check_one_row_each(table: pd.DataFrame, conditions: Sequence[str], what: str) -> None:
    """A :class:`UserError` when ``table`` has several rows for one participant x condition."""
    dup = table.duplicated(["participant", *conditions], keep=False)
    if dup.any():
        first = table[dup].iloc[0]
        raise UserError(f"{what} needs one row per participant x condition; "
                        f"{cell_name(first['participant'], conditions, [first[c] for c in conditions])} has "
                        f"{int(dup.sum())} duplicated rows: pass the table its per-participant function made, "
                        f"with the same condition columns")


def summary(rate_table: pd.DataFrame, conditions: Sequence[str] = (), ci_level: float = 0.95) -> pd.DataFrame:
    """Mean d' and c across participants per condition, with t intervals (:func:`t_summary`).

    ``rate_table`` is :func:`rates`'s output. One row per condition and measure ('d_prime', 'criterion'),
    with :func:`t_summary`'s columns plus ``n_extreme_rate``: how many participants' values came from a
    raw rate of 0 or 1 (their d' rests on the correction). Fewer than 2 participants: flagged ``n_below_2``.
    """
    conditions = list(conditions)
    require_columns(rate_table, ["participant", *conditions, "d_prime", "criterion", "extreme_rate"], "summary")
    check_one_row_each(rate_table, conditions, "summary")
    out = t_summary(rate_table, conditions, ["d_prime", "criterion"], ci_level)
    extreme = rate_table.assign(_e=rate_table["extreme_rate"].astype(int))
    counts = (extreme.groupby(conditions, observed=True, dropna=False)["_e"].sum().reset_index()
              if conditions else pd.DataFrame({"_e": [int(extreme["_e"].sum())]}))
    out = out.merge(counts, on=conditions, how="left") if conditions else out.assign(_e=int(counts["_e"].iloc[0]))
    return out.rename(columns={"_e": "n_extreme_rate"})


__all__ = ["CORRECTION", "LOGLINEAR_ADD_COUNT", "LOGLINEAR_ADD_TRIALS", "RATE_COLUMNS", "SUMMARY_COLUMNS",
           "rates", "summary", "t_summary", "check_ci_level", "require_columns", "boolean_column", "cell_name",
           "check_one_row_each"]
