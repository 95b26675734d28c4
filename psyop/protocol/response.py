"""What the participant answers, and the schedule columns each kind of answer needs.

- ``two_interval``: which of two intervals showed more relative motion (detection,
  discrimination). Columns ``mode_interval1``, ``mode_interval2``, ``correct_interval``, the
  level column, and ``<factor>_interval1/2`` for factors an interval overrides.
- ``left_right_nearer``: which surface looked nearer (ordinal). Columns ``mode``,
  ``separation_D`` (the separation factor), ``near_side``.
- ``pairwise_preference``: which of two intervals looked more realistic. Columns ``mode_a``,
  ``mode_b``, ``pair``.
- ``reach``: blind reach to the remembered target (egocentric). Columns ``rendering``,
  ``target_fraction``, ``mode``.
- ``with_against``: did the scene move with the eye or against it (NC nulling, one interval). Columns
  ``mode`` (from the sign of the rendered NC), ``rendered_nc_mm`` (the signed NC rendered).
"""

from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import Field

from psyop.protocol.base import Number, StrictModel
from psyop.protocol.scene import RenderingMode

#: How an order or side is assigned. ``balanced``: within each condition, as evenly as possible
#: (an odd count gets its extra trial on a seeded random side). ``random``: a fair coin per trial.
Counterbalance = Literal["balanced", "random"]


class ModeFromFactor(StrictModel):
    """The rendering mode is the trial's level of a factor whose levels are mode names."""

    factor: str


class IntervalSpec(StrictModel):
    """One of the two stimuli of a 2AFC trial: its rendering mode and factor overrides
    (``set: {level_D: 0}`` shows the reference with the level at 0)."""

    mode: RenderingMode | ModeFromFactor
    set: dict[str, Number] = Field(default_factory=dict)


class TwoIntervalResponse(StrictModel):
    """Two-interval forced choice; the ``test`` interval is the correct answer."""

    kind: Literal["two_interval"]
    question: str = "Which interval showed more relative motion?"
    test: IntervalSpec
    reference: IntervalSpec
    level_factor: str = "level_D"
    order: Counterbalance = "balanced"


class LeftRightNearerResponse(StrictModel):
    """Which side (left/right) of a border looked nearer."""

    kind: Literal["left_right_nearer"]
    question: str = "Which surface appeared nearer, left or right?"
    mode: RenderingMode | ModeFromFactor = ModeFromFactor(factor="mode")
    separation_factor: str = "separation_D"
    near_side: Counterbalance = "balanced"


class PairwisePreferenceResponse(StrictModel):
    """Which of two intervals (modes ``a`` then ``b``) looked more realistic. The pair factor's
    levels are written ``first|second``; ``order`` counterbalances which is shown first."""

    kind: Literal["pairwise_preference"]
    question: str = "Which stimulus gave a stronger impression of realistic depth?"
    pair_factor: str = "pair"
    order: Counterbalance = "balanced"


def _reach_modes() -> dict[str, RenderingMode]:
    """The reach response's default modes: rendering factor level -> rendering mode."""
    return {"enabled": "ocular", "disabled": "conventional"}


class ReachResponse(StrictModel):
    """Blind reach. ``modes`` maps each level of the rendering factor to a rendering mode."""

    kind: Literal["reach"]
    question: str = "Reach to where the target was, then pull the trigger."
    rendering_factor: str = "rendering"
    target_factor: str = "target_fraction"
    modes: dict[str, RenderingMode] = Field(default_factory=_reach_modes)
    average_last_samples: Annotated[int, Field(ge=1, le=10000)] = 10


class WithAgainstResponse(StrictModel):
    """NC nulling (docs/protocols.md, "NC calibration"): one interval rendered with the trial's signed NC
    (``display.rendering_nc`` with ``signed: true`` reading ``nc_factor``: > 0 ocular, 0 conventional,
    < 0 reversed); the participant answers whether the scene moved ``with`` the eye or ``against`` it."""

    kind: Literal["with_against"]
    question: str = "Did the scene move with your eye or against it?"
    nc_factor: str = "nc_mm"


Response = Annotated[
    Union[TwoIntervalResponse, LeftRightNearerResponse, PairwisePreferenceResponse, ReachResponse,
          WithAgainstResponse],
    Field(discriminator="kind"),
]

#: Number of interval phases each response kind needs.
INTERVALS_NEEDED: dict[str, int] = {"two_interval": 2, "left_right_nearer": 1, "pairwise_preference": 2, "reach": 1,
                                   "with_against": 1}

