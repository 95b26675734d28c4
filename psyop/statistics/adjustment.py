"""Method of adjustment: the point of subjective equality (PSE), its bias from the reference and the
precision (SD) of the settings, per participant and condition, and their means across participants.

Input is a tidy trial table, one row per trial: ``participant``, the condition columns the caller names,
``final_value`` (the setting the participant ended the trial on) and ``reference_value`` (the value a
perfect match would give; it may change from trial to trial). All values are in the units of
``final_value`` (dioptres, degrees, ...), which this module does not know.

The SD (ddof 1) of n normal settings underestimates their sigma by the factor c4(n) (0.973 at n = 10,
0.92 at n = 4): the mean SD across participants estimates c4(n) * sigma, not sigma (:func:`c4`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from psyop.errors import UserError
from psyop.statistics.anova import AnovaResult, rm_anova
from psyop.statistics.signal_detection import cell_name, check_one_row_each, require_columns, t_summary

PSE_COLUMNS = ["n", "pse", "reference", "bias", "sd", "flags"]
#: flags of :func:`pse_by_participant`: fewer than 2 trials (sd NaN); a reference that changes within the cell
#: (``pse`` and ``reference`` are then means over different references; ``bias`` and ``sd`` use the per-trial
#: errors, final - reference)
FLAG_N_BELOW_2, FLAG_REFERENCE_VARIES = "n_below_2", "reference_varies"


def c4(n: int) -> float:
    """E[SD] / sigma for n normal values (SD with ddof 1).

    Examples
    --------
    >>> round(c4(10), 4), round(c4(2), 4)
    (0.9727, 0.7979)
    """
    if n < 2:
        raise ValueError(f"c4 needs n >= 2, got {n}")
    return math.sqrt(2.0 / (n - 1)) * math.exp(math.lgamma(n / 2.0) - math.lgamma((n - 1) / 2.0))


def _finite(trials: pd.DataFrame, column: str, keys: Sequence[str], conditions: Sequence[str]) -> np.ndarray:
    values = pd.to_numeric(trials[column], errors="coerce").to_numpy(float)
    bad = ~np.isfinite(values)
    if bad.any():
        row = trials[bad].iloc[0]
        where = cell_name(row["participant"], conditions, [row[c] for c in conditions])
        raise UserError(f"column {column!r} has {int(bad.sum())} missing or non-numeric value(s) (first in {where}, "
                        f"value {trials[column][bad].iloc[0]!r}): drop the unfinished trials first")
    return values


def pse_by_participant(trials: pd.DataFrame, conditions: Sequence[str] = ()) -> pd.DataFrame:
    """PSE, bias and SD of the settings per participant x condition.

    Columns: ``participant``, the condition columns, then :data:`PSE_COLUMNS`: ``n`` trials, ``pse`` =
    mean(final_value), ``reference`` = mean(reference_value), ``bias`` = mean(final_value - reference_value)
    (= pse - reference), ``sd`` = SD(final_value - reference_value) with ddof 1 (= SD(final_value) when the
    reference is constant; NaN and flagged ``n_below_2`` for one trial) and ``flags`` (';'-joined).

    Examples
    --------
    >>> t = pd.DataFrame({"participant": "p1", "final_value": [1.1, 1.3], "reference_value": 1.0})
    >>> r = pse_by_participant(t).iloc[0]
    >>> round(float(r["pse"]), 3), round(float(r["bias"]), 3), round(float(r["sd"]), 4), r["flags"]
    (1.2, 0.2, 0.1414, '')
    """
    conditions = list(conditions)
    keys = ["participant", *conditions]
    require_columns(trials, [*keys, "final_value", "reference_value"], "pse_by_participant")
    final = _finite(trials, "final_value", keys, conditions)
    reference = _finite(trials, "reference_value", keys, conditions)
    data = trials[keys].assign(final=final, reference=reference, error=final - reference)
    g = data.groupby(keys, observed=True, sort=True, dropna=False)
    out = g.agg(n=("final", "size"), pse=("final", "mean"), reference=("reference", "mean"),
                bias=("error", "mean"), sd=("error", "std"), ref_min=("reference", "min"),
                ref_max=("reference", "max")).reset_index()
    out["sd"] = out["sd"].where(out["n"] >= 2)
    varies = ~np.isclose(out["ref_min"], out["ref_max"], rtol=1e-12, atol=0.0)
    out["flags"] = [";".join(f for f, on in ((FLAG_N_BELOW_2, n < 2), (FLAG_REFERENCE_VARIES, v)) if on)
                    for n, v in zip(out["n"], varies)]
    return out[[*keys, *PSE_COLUMNS]]


@dataclass(frozen=True)
class AdjustmentSummary:
    """Per-condition means across participants (``table``: :func:`psyop.statistics.signal_detection.t_summary`'s
    columns, one row per condition and measure 'pse', 'bias', 'sd') and the repeated-measures ANOVA of the PSE
    over the condition factors (``anova``; None with the reason in ``anova_note`` when it cannot be run)."""

    table: pd.DataFrame
    anova: AnovaResult | None
    anova_note: str = ""


def _pse_anova(pse_table: pd.DataFrame, conditions: Sequence[str]) -> tuple[AnovaResult | None, str]:
    factors = [c for c in conditions if pse_table[c].nunique() >= 2]
    if not factors:
        return None, "no condition factor with 2 or more levels: no ANOVA of the PSE"
    if len(factors) > 2:
        return None, (f"{len(factors)} condition factors ({', '.join(factors)}): the repeated-measures ANOVA takes "
                      "one or two; cross them into one column to test the cells")
    single = [c for c in conditions if c not in factors]
    data = pse_table.drop(columns=single)
    try:
        return rm_anova(data, "pse", factors), ""
    except UserError as exc:
        return None, f"ANOVA of the PSE not run: {exc}"


def summary(pse_table: pd.DataFrame, conditions: Sequence[str] = (), ci_level: float = 0.95,
            with_anova: bool = True) -> AdjustmentSummary:
    """Mean PSE, bias and SD across participants per condition (t intervals) and the RM-ANOVA of the PSE
    (:func:`psyop.statistics.anova.rm_anova`, Greenhouse-Geisser) over the condition factors that have
    2 or more levels (one or two factors).

    ``pse_table`` is :func:`pse_by_participant`'s output. A participant with one trial (sd NaN) is left out
    of the mean SD and counted in ``n_excluded``. The ANOVA drops participants with a missing cell and says
    whom (``anova.dropped``); data it cannot test (e.g. too few participants) give ``anova`` None and the
    reason in ``anova_note``. ``with_anova=False`` skips it (``anova`` None, the note says so).
    """
    conditions = list(conditions)
    require_columns(pse_table, ["participant", *conditions, "pse", "bias", "sd"], "summary")
    check_one_row_each(pse_table, conditions, "summary")
    table = t_summary(pse_table, conditions, ["pse", "bias", "sd"], ci_level)
    anova, note = _pse_anova(pse_table, conditions) if with_anova else (None, "not requested (with_anova=False)")
    return AdjustmentSummary(table=table, anova=anova, anova_note=note)


__all__ = ["PSE_COLUMNS", "AdjustmentSummary", "c4", "pse_by_participant", "summary"]
