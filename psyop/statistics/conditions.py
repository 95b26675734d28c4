"""The condition a two-interval study's thresholds are compared over, for factors of any type.

A threshold study fits one psychometric function per participant and condition. The condition is
the design's factor other than the level factor; its levels may be numbers (``back_D: [1, 2, 3]``)
or words (``mode: [ocular, reversed]``). A design that crosses several such factors (numbers and
words mixed, ``back_D`` x ``mode``) is compared over its crossed cells: one condition per cell, in
the column :data:`CELL_COLUMN` (``"back_D=1, mode=ocular"``), so every threshold belongs to exactly
one cell and nothing is pooled over a factor unseen. analysis/fit_psychometric.py and psyop power
(psyop.power.study_tests) both take the condition from here, so power tests what the figures report.
"""

from __future__ import annotations

from collections.abc import Sequence

import pandas as pd

#: the condition column of a design that crosses several condition factors (one level per cell)
CELL_COLUMN = "condition_cell"


def level_text(value: object) -> str:
    """A factor level as text: numbers without trailing zeros, words as they are.

    Examples
    --------
    >>> level_text(1.0), level_text(0.25), level_text("ocular")
    ('1', '0.25', 'ocular')
    """
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return f"{value:g}"
    return str(value)


def numeric_levels(values: pd.Series) -> bool:
    """Whether every level is a number (a factor of words, or one that mixes words in, is not).

    Examples
    --------
    >>> numeric_levels(pd.Series([1.0, 2.0])), numeric_levels(pd.Series(["ocular", "reversed"]))
    (True, False)
    """
    return bool(len(values)) and bool(pd.to_numeric(values, errors="coerce").notna().all())


def condition_of(factors: Sequence[str]) -> str:
    """The column thresholds are compared over: the one condition factor, or :data:`CELL_COLUMN`
    when there are several (their crossed cells); a ValueError when there is none."""
    if not factors:
        raise ValueError("a threshold study needs a condition factor besides the level factor")
    return factors[0] if len(factors) == 1 else CELL_COLUMN


def cell_label(factors: Sequence[str], values: Sequence[object]) -> str:
    """One crossed cell's name.

    Examples
    --------
    >>> cell_label(["back_D", "mode"], [1.0, "ocular"])
    'back_D=1, mode=ocular'
    """
    return ", ".join(f"{f}={level_text(v)}" for f, v in zip(factors, values))


def with_condition(trials: pd.DataFrame, factors: Sequence[str]) -> pd.DataFrame:
    """``trials`` with the condition column of :func:`condition_of` (a copy with :data:`CELL_COLUMN`
    added when there are several condition factors; ``trials`` itself otherwise)."""
    if condition_of(factors) != CELL_COLUMN or CELL_COLUMN in trials:
        return trials
    missing = [f for f in factors if f not in trials]
    if missing:
        raise ValueError(f"no column {', '.join(map(repr, missing))} for the crossed conditions")
    out = trials.copy()
    out[CELL_COLUMN] = [cell_label(factors, row) for row in zip(*(out[f] for f in factors))]
    return out


def describe(factors: Sequence[str]) -> str:
    """What :func:`condition_of` compares, in words: the factor, or the crossed cells of several.

    Examples
    --------
    >>> describe(["back_D"]), describe(["back_D", "mode"])
    ('back_D', 'the crossed cells of back_D x mode')
    """
    return factors[0] if len(factors) == 1 else f"the crossed cells of {' x '.join(factors)}"
