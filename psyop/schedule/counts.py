"""How many trials a protocol schedules and how long it takes: from the design alone, no
schedule built (light to import: ``psyop validate`` and ``psyop show`` use it)."""

from __future__ import annotations

from psyop.protocol.conditions import expand_conditions
from psyop.protocol.model import Protocol


def expected_duration_s(protocol: Protocol) -> float:
    """Expected session length (s): trials (practice included) x expected trial length."""
    return trial_count(protocol) * protocol.trial.expected_duration_s()


def trial_count(protocol: Protocol) -> int:
    """Rows of the schedule (practice included)."""
    design = protocol.design
    return len(expand_conditions(design)) * design.repetitions + design.practice_trials
