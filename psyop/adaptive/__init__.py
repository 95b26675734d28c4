"""Adaptive procedures: pure state machines over a condition's (level, response) history.

Every procedure answers ``state(history) -> ProcedureState`` (next level, running estimate,
whether it has stopped) and keeps nothing between calls, so a session rebuilds it from its own
trial log after a crash: there is no procedure state file to lose.
"""

from psyop.adaptive.history import Observation
from psyop.adaptive.interleave import Interleaved, Step, split_history
from psyop.adaptive.procedure import Procedure, make_procedure
from psyop.adaptive.quest_plus import QuestPlus, QuestPlusSpec
from psyop.adaptive.staircase import Staircase, StaircaseSpec
from psyop.adaptive.state import ProcedureState
from psyop.adaptive.stopping import StopRule

__all__ = ["Interleaved", "Observation", "Procedure", "ProcedureState", "QuestPlus", "QuestPlusSpec",
           "Staircase", "StaircaseSpec", "Step", "StopRule", "make_procedure", "split_history"]
