"""The protocol's ``response:`` section: one of the response kinds (psyop.protocol.kinds, one module per kind),
chosen by its ``kind`` field. docs/protocols.md describes each kind; docs/architecture.md says how to add one.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Union

from pydantic import Field

from psyop.protocol.kinds import response_models
from psyop.protocol.kinds.base import Counterbalance, IntervalSpec, KindResponse, ModeFromFactor
from psyop.protocol.kinds.left_right_nearer import LeftRightNearerResponse
from psyop.protocol.kinds.pairwise_preference import PairwisePreferenceResponse
from psyop.protocol.kinds.reach import ReachResponse
from psyop.protocol.kinds.two_interval import TwoIntervalResponse
from psyop.protocol.kinds.with_against import WithAgainstResponse

if TYPE_CHECKING:
    #: one response, of any kind (the kinds' common base: code above the protocol dispatches on the kind object)
    Response = KindResponse
else:
    #: The protocol's ``response:`` section: one of the kinds, chosen by its ``kind`` field.
    Response = Annotated[Union[response_models()], Field(discriminator="kind")]

ResponseModel = KindResponse

__all__ = ["Counterbalance", "IntervalSpec", "KindResponse", "LeftRightNearerResponse", "ModeFromFactor",
           "PairwisePreferenceResponse", "ReachResponse", "Response", "ResponseModel", "TwoIntervalResponse",
           "WithAgainstResponse"]
