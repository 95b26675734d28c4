"""The columns a 2AFC (two-interval) study's analysis groups by: the condition column (the design's
factor other than the level factor) and the level column (the response's ``level_factor``), read
from the protocol its sessions ran (psyop.statistics.studies), or given on the command line."""

from __future__ import annotations

import pandas as pd

from psyop.errors import UserError
from psyop.statistics.conditions import CELL_COLUMN, condition_of, describe, with_condition
from psyop.statistics.studies import FactorFacts, StudyFacts

#: Studies whose sessions carry no protocol (older logs, write_dataset without hashes): the paper's names.
KNOWN_CONDITIONS = {"detection": "back_D", "discrimination": "offset_D"}
#: the one condition of a study whose only factor is the level (its ``condition_cell``)
ONE_CONDITION = "all"


def condition_column(facts: StudyFacts, given: str | None) -> str:
    """``given``, else the protocol's one non-level factor, else (several: numbers and words mixed, say)
    the column of their crossed cells (psyop.statistics.conditions.CELL_COLUMN); a UserError when there is none."""
    if given:
        return given
    candidates = facts.condition_columns()
    if not candidates and not facts.factors and facts.name in KNOWN_CONDITIONS:
        return KNOWN_CONDITIONS[facts.name]
    if not candidates and not facts.factors:
        raise UserError(f"study {facts.name!r}: its sessions record no protocol, so its condition factor is unknown; "
                        "give --condition-column", facts.name)
    if not candidates:  # the level is the design's only factor: one threshold per participant, one condition
        return CELL_COLUMN
    return condition_of(candidates)


def with_condition_column(trials: pd.DataFrame, facts: StudyFacts, condition: str) -> pd.DataFrame:
    """``trials`` with the crossed-cell column added when ``condition`` is it (several condition factors)."""
    if condition != CELL_COLUMN:
        return trials
    if not facts.condition_columns():  # the level is the only factor: every trial in the one condition
        return trials.assign(**{CELL_COLUMN: ONE_CONDITION})
    try:
        return with_condition(trials, facts.condition_columns())
    except ValueError as exc:
        raise UserError(f"study {facts.name!r}: {exc}; give --condition-column", facts.name) from None


def condition_facts(facts: StudyFacts, condition: str) -> FactorFacts:
    """The condition's name, description and unit for labels (the crossed cells say which factors they cross)."""
    if condition == CELL_COLUMN and len(facts.condition_columns()) > 1:
        return FactorFacts(CELL_COLUMN, describe(facts.condition_columns()), None)
    if condition == CELL_COLUMN and not facts.condition_columns():
        return FactorFacts(CELL_COLUMN, "all trials (the level is the only factor)", None)
    return facts.factor(condition)


def level_column(facts: StudyFacts, given: str | None) -> str:
    """``given``, else the response's level factor."""
    return given or facts.level_factor or "level_D"


def check_two_interval(facts: StudyFacts, script: str) -> None:
    if facts.kind.name != "two_interval":
        raise UserError(f"study {facts.name!r} has {facts.kind.name} responses; {script} analyses two-interval "
                        "(2AFC) studies (`python -m psyop studies DATA` lists each study's kind)", facts.name)
