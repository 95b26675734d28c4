"""The columns a 2AFC (two-interval) study's analysis groups by: the condition column (the design's
factor other than the level factor) and the level column (the response's ``level_factor``), read
from the protocol its sessions ran (psyop.statistics.studies), or given on the command line."""

from __future__ import annotations

from psyop.errors import UserError
from psyop.session.responses.base import ResponseKind
from psyop.statistics.studies import StudyFacts

#: Studies whose sessions carry no protocol (older logs, write_dataset without hashes): the paper's names.
KNOWN_CONDITIONS = {"detection": "back_D", "discrimination": "offset_D"}


def condition_column(facts: StudyFacts, given: str | None) -> str:
    """``given``, else the protocol's one non-level factor; a UserError when there is none or several."""
    if given:
        return given
    candidates = facts.condition_columns()
    if len(candidates) == 1:
        return candidates[0]
    if not facts.factors and facts.name in KNOWN_CONDITIONS:
        return KNOWN_CONDITIONS[facts.name]
    if not candidates:
        raise UserError(f"study {facts.name!r}: no condition factor besides the level factor {facts.level_factor!r} "
                        "(its sessions record no protocol, or the design has one factor); give --condition-column",
                        facts.name)
    raise UserError(f"study {facts.name!r} has several condition factors ({', '.join(candidates)}); give "
                    "--condition-column NAME for the one to fit thresholds over", facts.name)


def level_column(facts: StudyFacts, given: str | None) -> str:
    """``given``, else the response's level factor."""
    return given or facts.level_factor or "level_D"


def check_two_interval(facts: StudyFacts, script: str) -> None:
    if facts.kind is not ResponseKind.TWO_INTERVAL:
        raise UserError(f"study {facts.name!r} has {facts.kind.value} responses; {script} analyses two-interval "
                        "(2AFC) studies (`python -m psyop studies DATA` lists each study's kind)", facts.name)
