"""The one interface the session and the simulations use: ``procedure.state(history)``."""

from __future__ import annotations

from typing import Protocol, Sequence

from psyop.adaptive.history import Observation
from psyop.adaptive.quest_plus import QuestPlus, QuestPlusSpec
from psyop.adaptive.staircase import Staircase, StaircaseSpec
from psyop.adaptive.state import ProcedureState


class Procedure(Protocol):
    name: str

    def state(self, history: Sequence[Observation]) -> ProcedureState: ...


def make_procedure(spec: QuestPlusSpec | StaircaseSpec) -> Procedure:
    """The procedure for a spec (QUEST+ precomputes its likelihood table once here)."""
    if isinstance(spec, QuestPlusSpec):
        return QuestPlus(spec)
    if isinstance(spec, StaircaseSpec):
        return Staircase(spec)
    raise TypeError(f"no procedure for {type(spec).__name__}")
