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

The kinds are one closed set, :data:`Response` (a union discriminated by ``kind``). What a kind
is at the protocol level (how many interval phases it needs, which simulated observer answers
it, how its binary choice is counterbalanced) is declared on its class here. The layers above
dispatch on the union with one ``match`` each, closed by ``assert_never`` so that mypy names
every place a new kind must be handled: the semantic checks (psyop.protocol.semantics,
``check_response``), the schedule columns (psyop.schedule.compile, ``_response_columns``) and
the session plan (psyop.session.plan, ``session_response_kind``). Adding a kind: its class here,
added to :data:`Response`; then mypy lists the ``match`` statements that miss it.
"""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal, Union

from pydantic import Field

from psyop.protocol.base import Number, StrictModel
from psyop.protocol.scene import RenderingMode

#: How an order or side is assigned. ``balanced``: within each condition, as evenly as possible
#: (an odd count gets its extra trial on a seeded random side). ``random``: a fair coin per trial.
Counterbalance = Literal["balanced", "random"]


class ModeFromFactor(StrictModel):
    """The rendering mode is the trial's level of a factor whose levels are mode names."""

    factor: str


def _mode_factor(mode: RenderingMode | ModeFromFactor) -> set[str]:
    """The factor a mode is read from ({} for a fixed mode)."""
    return {mode.factor} if isinstance(mode, ModeFromFactor) else set()


class IntervalSpec(StrictModel):
    """One of the two stimuli of a 2AFC trial: its rendering mode and factor overrides
    (``set: {level_D: 0}`` shows the reference with the level at 0)."""

    mode: RenderingMode | ModeFromFactor
    set: dict[str, Number] = Field(default_factory=dict)


class TwoIntervalResponse(StrictModel):
    """Two-interval forced choice; the ``test`` interval is the correct answer."""

    kind: Literal["two_interval"]
    intervals_needed: ClassVar[int] = 2
    observer_kind: ClassVar[str] = "psychometric_2afc"
    question: str = "Which interval showed more relative motion?"
    test: IntervalSpec
    reference: IntervalSpec
    level_factor: str = "level_D"
    order: Counterbalance = "balanced"

    @property
    def counterbalance(self) -> Counterbalance:
        """How the interval order (test first or second) is assigned."""
        return self.order

    def interval_specs(self) -> tuple[IntervalSpec, ...]:
        """The intervals' specs: (test, reference)."""
        return (self.test, self.reference)

    def factors_read(self) -> set[str]:
        """The factors this response reads: the level, each interval's mode factor and ``set:`` keys."""
        used = {self.level_factor}
        for spec in self.interval_specs():
            used |= _mode_factor(spec.mode) | set(spec.set)
        return used


class LeftRightNearerResponse(StrictModel):
    """Which side (left/right) of a border looked nearer."""

    kind: Literal["left_right_nearer"]
    intervals_needed: ClassVar[int] = 1
    observer_kind: ClassVar[str] = "ordinal_accuracy"
    question: str = "Which surface appeared nearer, left or right?"
    mode: RenderingMode | ModeFromFactor = ModeFromFactor(factor="mode")
    separation_factor: str = "separation_D"
    near_side: Counterbalance = "balanced"

    @property
    def counterbalance(self) -> Counterbalance:
        """How the near side is assigned."""
        return self.near_side

    def interval_specs(self) -> tuple[IntervalSpec, ...]:
        """No per-interval specs (one interval, the mode above)."""
        return ()

    def factors_read(self) -> set[str]:
        """The separation factor and the mode factor."""
        return {self.separation_factor} | _mode_factor(self.mode)


class PairwisePreferenceResponse(StrictModel):
    """Which of two intervals (modes ``a`` then ``b``) looked more realistic. The pair factor's
    levels are written ``first|second``; ``order`` counterbalances which is shown first."""

    kind: Literal["pairwise_preference"]
    intervals_needed: ClassVar[int] = 2
    observer_kind: ClassVar[str] = "pairwise_preference"
    question: str = "Which stimulus gave a stronger impression of realistic depth?"
    pair_factor: str = "pair"
    order: Counterbalance = "balanced"

    @property
    def counterbalance(self) -> Counterbalance:
        """How the pair order (which mode is shown first) is assigned."""
        return self.order

    def interval_specs(self) -> tuple[IntervalSpec, ...]:
        """No per-interval specs (the pair level names both modes)."""
        return ()

    def factors_read(self) -> set[str]:
        """The pair factor."""
        return {self.pair_factor}


def _reach_modes() -> dict[str, RenderingMode]:
    """The reach response's default modes: rendering factor level -> rendering mode."""
    return {"enabled": "ocular", "disabled": "conventional"}


class ReachResponse(StrictModel):
    """Blind reach. ``modes`` maps each level of the rendering factor to a rendering mode."""

    kind: Literal["reach"]
    intervals_needed: ClassVar[int] = 1
    observer_kind: ClassVar[str] = "reach"
    question: str = "Reach to where the target was, then pull the trigger."
    rendering_factor: str = "rendering"
    target_factor: str = "target_fraction"
    modes: dict[str, RenderingMode] = Field(default_factory=_reach_modes)
    average_last_samples: Annotated[int, Field(ge=1, le=10000)] = 10

    @property
    def counterbalance(self) -> Counterbalance:
        """Reach has no binary choice: the stream is drawn balanced and unused."""
        return "balanced"

    def interval_specs(self) -> tuple[IntervalSpec, ...]:
        """No per-interval specs (the modes map the rendering factor)."""
        return ()

    def factors_read(self) -> set[str]:
        """The rendering and target factors."""
        return {self.rendering_factor, self.target_factor}


class WithAgainstResponse(StrictModel):
    """NC nulling (docs/protocols.md, "NC calibration"): one interval rendered with the trial's signed NC
    (``display.rendering_nc`` with ``signed: true`` reading ``nc_factor``: > 0 ocular, 0 conventional,
    < 0 reversed); the participant answers whether the scene moved ``with`` the eye or ``against`` it."""

    kind: Literal["with_against"]
    intervals_needed: ClassVar[int] = 1
    observer_kind: ClassVar[str] = "nc_nulling"
    question: str = "Did the scene move with your eye or against it?"
    nc_factor: str = "nc_mm"

    @property
    def counterbalance(self) -> Counterbalance:
        """NC nulling has no binary choice: the stream is drawn balanced and unused."""
        return "balanced"

    def interval_specs(self) -> tuple[IntervalSpec, ...]:
        """No per-interval specs (the NC factor's sign is the mode)."""
        return ()

    def factors_read(self) -> set[str]:
        """The signed NC factor."""
        return {self.nc_factor}


#: One response, of any kind (what ``match`` statements over the kinds narrow).
ResponseModel = Union[TwoIntervalResponse, LeftRightNearerResponse, PairwisePreferenceResponse, ReachResponse,
                      WithAgainstResponse]
#: The protocol's ``response:`` section: one of the kinds, chosen by its ``kind`` field.
Response = Annotated[ResponseModel, Field(discriminator="kind")]
