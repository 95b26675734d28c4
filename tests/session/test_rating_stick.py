"""The scale picker a rating and a confidence rating use with the OpenXR controllers (psyop.session.scale_picker):
its flick, dead-zone and re-arm rule on raw stick inputs, the path it logs, and the text the panel shows with the
highlighted point marked, laid out and checked before the session. The controllers themselves answer on the real
runtime in tests/devices/xr/test_openxr_rating.py."""

from __future__ import annotations

import json
from pathlib import Path

from psyop.protocol import load_protocol
from psyop.protocol.kinds.confidence import SCALE_AXIS, SCALE_CONFIRM, STICK_HELP, ConfidenceScale, confidence_text
from psyop.protocol.kinds.rating import RatingResponse
from psyop.session.plan import compile_plan
from psyop.session.rating_stick import marked_text, marked_texts
from psyop.session.responses.base import RawInput
from psyop.session.scale_picker import FLICK_AT, REARM_BELOW, ScalePicker, start_point

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "protocols" / "examples" / "rating.yaml"


def _picked(points: int, inputs: list[tuple[float, float | None]]) -> ScalePicker:
    """A picker shown at t = 0 fed (time, stick x) inputs; x None is a select button."""
    picker = ScalePicker(points, t0_s=0.0)
    for t_s, x in inputs:
        picker.apply(RawInput(SCALE_CONFIRM, t_s) if x is None else RawInput(SCALE_AXIS, t_s, x))
    return picker


def test_a_flick_moves_one_point_and_the_stick_must_come_back_before_the_next() -> None:
    assert FLICK_AT > REARM_BELOW  # a dead band between: a stick wobbling near the threshold flicks once
    held = _picked(7, [(0.1, 0.7), (0.2, 1.0), (0.3, 0.9), (0.4, 0.4), (0.5, 0.8), (0.6, None)])
    assert held.point == start_point(7) + 1 == 5  # held over, and back only to 0.4: still the one step
    twice = _picked(7, [(0.1, 1.0), (0.2, 0.1), (0.3, 0.65), (0.4, 0.0), (0.5, None)])
    assert twice.point == 6 and twice.confirmed_s == 0.5
    assert json.loads(twice.path_json()) == [[0.0, 4], [0.1, 5], [0.3, 6]]
    weak = _picked(7, [(0.1, FLICK_AT - 0.01), (0.2, 0.0), (0.3, -FLICK_AT), (0.4, 0.0)])
    assert weak.point == 3 and weak.confirmed_s is None  # below the threshold: nothing; a left flick: one down


def test_the_ends_stop_the_marker_and_nothing_counts_after_the_confirmation() -> None:
    flicks = [(0.1 * k, 1.0 if k % 2 else 0.0) for k in range(1, 9)]  # four right flicks on a 4-point scale
    picker = _picked(4, flicks + [(1.0, None), (1.1, 0.0), (1.2, -1.0), (1.3, None)])
    assert picker.point == 4 and picker.confirmed_s == 1.0
    assert [p for _, p in picker.path] == [2, 3, 4, 4, 4]  # every flick is a path entry, also one an end stops


def test_the_panel_marks_the_highlighted_point_and_every_marked_text_is_laid_out_first() -> None:
    protocol = load_protocol(EXAMPLE)
    assert isinstance(protocol.response, RatingResponse)
    plan = compile_plan(protocol, responses="openxr")
    assert plan.response.answer_keys == STICK_HELP and plan.response.participant_text is not None
    texts = marked_texts(plan)
    points = int(protocol.response.scale.points)
    assert len(texts) == points and texts[2] == marked_text(plan.response, protocol.response, 3)
    labels = protocol.response.scale.labels or []
    marked = [line for line in texts[2].splitlines() if line.startswith(">")]
    assert marked == [f">  3  {labels[2]}  <"]
    assert marked_texts(compile_plan(protocol, responses="keyboard")) == []  # keys answer by digit, unmarked
    row = confidence_text(ConfidenceScale(points=4), highlighted=2).splitlines()[-1]
    assert row == "1  [2]  3  4"
