"""Simulated-observer parameters (``observer:`` section).

Each response kind (psyop.protocol.kinds) owns the observer models that may answer it, their behaviour
included (psyop.session.responses.simulated draws for them); this is their
union, discriminated by ``kind``. See docs/architecture.md, "Simulated observers".
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Union

from pydantic import Field

from psyop.protocol.kinds import observer_models
from psyop.protocol.kinds.base import ObserverBase
from psyop.protocol.kinds.left_right_nearer import OrdinalAccuracy
from psyop.protocol.kinds.pairwise_preference import PairwisePreference
from psyop.protocol.kinds.reach import Reach, ReachCondition
from psyop.protocol.kinds.two_interval import Psychometric2afc
from psyop.protocol.kinds.with_against import NcNulling

if TYPE_CHECKING:
    Observer = ObserverBase
else:
    Observer = Annotated[Union[observer_models()], Field(discriminator="kind")]

__all__ = ["NcNulling", "Observer", "ObserverBase", "OrdinalAccuracy", "PairwisePreference", "Psychometric2afc",
           "Reach", "ReachCondition"]
