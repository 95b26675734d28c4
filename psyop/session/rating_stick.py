"""A rating's response phase answered with the OpenXR controllers (``kind: rating`` with ``--responses openxr``):
the response text is drawn each frame with the scale's point the stick highlights marked (psyop.session.scale_picker)
until a select button confirms it or the phase's ``timeout_s`` passes. The answer is the point (scored as a key's
would be), its time is the confirmation's from the phase's start, and the points highlighted go to ``rating_path``.
A keyboard or a response box answers a rating by digit, as ever (the loop's ``collect`` path)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

from psyop.datacontract import TIMEOUT_RESPONSE
from psyop.protocol.kinds.confidence import STICK_HELP
from psyop.protocol.kinds.rating import PATH_COLUMN, Rating, RatingResponse
from psyop.session.phases import PhaseSpec
from psyop.session.frames import FrameRequest
from psyop.session.plan import ResponsePlan, SessionPlan
from psyop.session.responses.base import Response, score
from psyop.session.rows import TrialRow
from psyop.session.scale_picker import MappedRawSource, PickerPacing, ScalePicker, run_picker
from psyop.session.screens import ScreenPhase


def marked_text(plan: ResponsePlan, rating: RatingResponse, point: int) -> str:
    """The response phase's text (:attr:`ResponsePlan.participant_text`: the question, the stick's help, the scale)
    with the scale's ``point`` marked."""
    text, scale = plan.participant_text or "", (plan.response_text or "").strip()
    head = text.removesuffix(scale) if scale and text.endswith(scale) else text + "\n\n"
    return head + Rating.scale_text(rating, point)


def marked_texts(plan: SessionPlan) -> list[str]:
    """Every text a rating answered with the controllers can draw (one per highlighted point), for the session's
    legibility check before the first trial; [] for another kind or source (a default prompt then names no stick:
    the plan was made for another ``--responses``)."""
    rating, response = plan.protocol.response, plan.response
    if not isinstance(rating, RatingResponse) or response.answer_keys != STICK_HELP:
        return []
    return [marked_text(response, rating, point) for point in range(1, int(rating.scale.points) + 1)]


def ask_rating(row: TrialRow, plan: ResponsePlan, rating: RatingResponse, source: MappedRawSource,
               pacing: PickerPacing, start_s: float, draw: Callable[[FrameRequest, PhaseSpec], object],
               phase_name: str = "response") -> Response:
    """One trial's rating picked with the stick from ``start_s`` (the response phase's start); ``draw`` renders a
    frame of a phase (the loop's frame path). A phase that times out is the timeout response, with its path."""

    def draw_marked(request: FrameRequest, point: int) -> object:
        return draw(request, ScreenPhase(phase_name, 0.0, "text", "cross", text=marked_text(plan, rating, point)))

    picker = run_picker(ScalePicker(int(rating.scale.points), start_s), source, pacing, draw_marked)
    extras = ((PATH_COLUMN, picker.path_json()),)
    if picker.confirmed_s is None:
        return Response(TIMEOUT_RESPONSE, correct=None, response_time_s=math.nan, extras=extras)
    scored = score(plan.kind, row, str(picker.point))
    return dataclasses.replace(scored, response_time_s=picker.confirmed_s - start_s, extras=extras)
