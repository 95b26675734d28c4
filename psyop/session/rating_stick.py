"""A trial's answer picked with the OpenXR controllers' stick (``--responses openxr``): a rating's point (``kind:
rating``) or one of an ``n_afc``'s n > 2 alternatives. The response text is drawn each frame with what the stick
highlights (psyop.session.scale_picker) until a select button confirms it or the phase's ``timeout_s`` passes:

- a rating: the scale under the question, its highlighted point marked (``>  3  label  <``, or ``[3]`` in a row of
  the digits without labels);
- an n_afc: a line naming the highlighted alternative under the question (``interval 3 of 4``, ``location 3 of 4``)
  and, over locations, a frame around the highlighted location (psyop.session.choice_marker).

The answer is the point or alternative (scored as its key's would be), its time is the confirmation's from the phase's
start, and the points highlighted go to the kind's path column (``rating_path``, ``choice_path``). A keyboard or a
response box answers by digit, as ever (the loop's ``collect`` path); an n_afc with n = 2 is answered with the two
select buttons.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

from psyop.datacontract import TIMEOUT_RESPONSE
from psyop.protocol.kinds.base import KindResponse
from psyop.protocol.kinds.confidence import STICK_HELP
from psyop.protocol.kinds.n_afc import CHOICE_PATH, NAfcResponse
from psyop.protocol.kinds.rating import PATH_COLUMN, Rating, RatingResponse
from psyop.session.phases import PhaseSpec
from psyop.session.frames import FrameRequest
from psyop.session.plan import ResponsePlan, SessionPlan
from psyop.session.responses.base import Response, score
from psyop.session.rows import TrialRow
from psyop.session.scale_picker import MappedRawSource, PickerPacing, ScalePicker, run_picker
from psyop.session.screens import ScreenPhase


@dataclass(frozen=True)
class StickQuestion:
    """The protocol's response when the controllers' stick picks its answer: a rating, or an n_afc with n > 2
    (:func:`stick_question`)."""

    response: RatingResponse | NAfcResponse

    @property
    def points(self) -> int:
        """How many answers the stick moves among (the scale's points, the alternatives)."""
        response = self.response
        return int(response.scale.points) if isinstance(response, RatingResponse) else int(response.n)

    @property
    def path_column(self) -> str:
        """The trial-log column of the highlighted path."""
        return PATH_COLUMN if isinstance(self.response, RatingResponse) else CHOICE_PATH

    def marked_text(self, plan: ResponsePlan, point: int) -> str:
        """The response phase's text (:attr:`ResponsePlan.participant_text`: the question, the stick's help, a
        rating's scale) with ``point`` marked: the scale's point, or a line naming the alternative."""
        response = self.response
        text = plan.participant_text or ""
        if isinstance(response, NAfcResponse):
            return f"{text}\n\n{response.alternative_text(point)}" if text else response.alternative_text(point)
        scale = (plan.response_text or "").strip()
        head = text.removesuffix(scale) if scale and text.endswith(scale) else text + "\n\n"
        return head + Rating.scale_text(response, point)

    def marker_deg(self, point: int) -> tuple[float, float] | None:
        """Where the highlighted alternative is, Fick [azimuth, elevation] in degrees (an n_afc over locations: its
        ``locations_deg`` entry), else None (nothing to mark in the scene)."""
        response = self.response
        if not isinstance(response, NAfcResponse) or response.locations_deg is None:
            return None
        azimuth, elevation = response.locations_deg[int(point) - 1]
        return (float(azimuth), float(elevation))


def stick_question(response: KindResponse) -> StickQuestion | None:
    """The :class:`StickQuestion` of a protocol's response when the controllers' stick picks its answer (a rating,
    an n_afc with n > 2), else None (the loop's ``collect`` path, buttons mapped to answers)."""
    if isinstance(response, RatingResponse) or (isinstance(response, NAfcResponse) and response.picks_with_stick()):
        return StickQuestion(response)
    return None


def marked_text(plan: ResponsePlan, rating: RatingResponse, point: int) -> str:
    """A rating's response text with the scale's ``point`` marked (:meth:`StickQuestion.marked_text`)."""
    return StickQuestion(rating).marked_text(plan, point)


def marked_texts(plan: SessionPlan) -> list[str]:
    """Every text an answer picked with the controllers can draw (one per highlighted point or alternative), for the
    session's legibility check before the first trial; [] for another kind or source (a default prompt then names no
    stick: the plan was made for another ``--responses``)."""
    question = stick_question(plan.protocol.response)
    if question is None or plan.response.answer_keys != STICK_HELP:
        return []
    return [question.marked_text(plan.response, point) for point in range(1, question.points + 1)]


def ask_on_stick(row: TrialRow, plan: ResponsePlan, question: StickQuestion, source: MappedRawSource,
                 pacing: PickerPacing, start_s: float, draw: Callable[[FrameRequest, PhaseSpec], object],
                 phase_name: str = "response") -> Response:
    """One trial's answer picked with the stick from ``start_s`` (the response phase's start); ``draw`` renders a
    frame of a phase (the loop's frame path). A phase that times out is the timeout response, with its path."""

    def draw_marked(request: FrameRequest, point: int) -> object:
        return draw(request, ScreenPhase(phase_name, 0.0, "text", "cross", text=question.marked_text(plan, point),
                                         marker_deg=question.marker_deg(point)))

    picker = run_picker(ScalePicker(question.points, start_s), source, pacing, draw_marked)
    extras = ((question.path_column, picker.path_json()),)
    if picker.confirmed_s is None:
        return Response(TIMEOUT_RESPONSE, correct=None, response_time_s=math.nan, extras=extras)
    scored = score(plan.kind, row, str(picker.point))
    return dataclasses.replace(scored, response_time_s=picker.confirmed_s - start_s, extras=extras)

