"""Several procedures, one per condition, randomly interleaved.

The next condition is drawn uniformly among the conditions whose procedure has not finished,
from a generator seeded by (seed, number of trials so far): the choice is a pure function of the
history, so a resumed session makes the same choice an uninterrupted one would.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from psyop.adaptive.history import Observation
from psyop.adaptive.procedure import Procedure
from psyop.adaptive.state import ProcedureState


@dataclass(frozen=True)
class Step:
    """The next trial: its condition and that condition's procedure state (``condition`` is None
    when every procedure has finished)."""

    condition: str | None
    state: ProcedureState | None


def split_history(conditions: Sequence[str], history: Sequence[tuple[str, Observation]]) -> dict[str, list[Observation]]:
    by_condition: dict[str, list[Observation]] = {c: [] for c in conditions}
    for condition, obs in history:
        if condition not in by_condition:
            raise ValueError(f"history names condition {condition!r}, not one of {list(conditions)}")
        by_condition[condition].append(obs)
    return by_condition


class Interleaved:
    """One procedure per condition (keys in a fixed order), interleaved at random."""

    def __init__(self, procedures: Mapping[str, Procedure], seed: int) -> None:
        if not procedures:
            raise ValueError("need at least one procedure")
        self.procedures = dict(procedures)
        self.seed = int(seed)

    def states(self, history: Sequence[tuple[str, Observation]]) -> dict[str, ProcedureState]:
        split = split_history(list(self.procedures), history)
        return {c: p.state(split[c]) for c, p in self.procedures.items()}

    def next(self, history: Sequence[tuple[str, Observation]]) -> Step:
        states = self.states(history)
        open_conditions = [c for c in self.procedures if not states[c].finished]
        if not open_conditions:
            return Step(None, None)
        rng = np.random.default_rng([self.seed, len(history)])
        condition = open_conditions[int(rng.integers(len(open_conditions)))]
        return Step(condition, states[condition])
