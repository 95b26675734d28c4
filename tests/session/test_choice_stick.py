"""An n_afc with n > 2 and a questionnaire item answered with the controllers' stick, without a runtime: the kind's
controller map (the two select buttons for n = 2, the scale's stick and buttons above), the response panel's line
naming the highlighted alternative, the picked answer scored with its ``choice_path`` (psyop.session.rating_stick on
a virtual clock), the frame marking a highlighted location drawn where the target is (headless EGL), and a
questionnaire item's marked point. The real runtime answers in tests/devices/xr/test_openxr_choice_stick.py."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from psyop.protocol import load_protocol
from psyop.protocol.kinds.confidence import SCALE_AXIS, SCALE_CONFIRM, SCALE_CONTROLLER, STICK_HELP
from psyop.protocol.kinds.n_afc import CHOICE_PATH, NAfcResponse
from psyop.protocol.session_screens import Questionnaire
from psyop.schedule import compile_schedule
from psyop.session.clock import VirtualClock
from psyop.session.frames import FrameRequest, HeadlessDisplay
from psyop.session.phases import PhaseSpec
from psyop.session.plan import compile_plan
from psyop.session.rating_stick import ask_on_stick, marked_texts, stick_question
from psyop.session.responses.base import RawInput
from psyop.session.scale_picker import PickerPacing
from psyop.session.screens import ScreenPhase, questionnaire_text

REPO = Path(__file__).resolve().parents[2]
LOCATIONS = REPO / "protocols" / "examples" / "n_afc_locations.yaml"
INTERVALS = REPO / "protocols" / "examples" / "n_afc.yaml"


class StickScript:
    """Raw stick and button inputs at stated times, each handed out once when its time has come (what
    psyop.devices.xr.tracking.OpenXRResponses.raw_inputs reports through the scale's map)."""

    keymap = SCALE_CONTROLLER

    def __init__(self, inputs: list[RawInput]) -> None:
        self.pending = sorted(inputs, key=lambda raw: raw.t_s)

    def raw_inputs(self, since_s: float, now_s: float) -> list[RawInput]:
        due = [raw for raw in self.pending if raw.t_s <= now_s]
        self.pending = self.pending[len(due):]
        return [raw for raw in due if raw.t_s >= since_s]


def test_two_alternatives_keep_the_select_buttons_and_more_are_picked_with_the_stick() -> None:
    two = compile_plan(load_protocol(INTERVALS), responses="openxr")
    assert isinstance(two.protocol.response, NAfcResponse)
    four = compile_plan(load_protocol(LOCATIONS), responses="openxr")
    assert four.response.inputs.controller == SCALE_CONTROLLER and four.response.answer_keys == STICK_HELP
    assert stick_question(four.protocol.response) is not None
    response = two.protocol.response.model_copy(update={"n": 2})
    plan2 = compile_plan(two.protocol.model_copy(update={"response": response}), responses="openxr")
    assert plan2.response.inputs.controller == {"left": "1", "right": "2"} and stick_question(response) is None
    texts = marked_texts(four)
    assert [text.splitlines()[-1] for text in texts] == [f"location {k} of 4" for k in range(1, 5)]
    assert texts[0].startswith(four.response.participant_text or "")
    assert marked_texts(compile_plan(load_protocol(LOCATIONS), responses="keyboard")) == []  # keys answer by digit


def test_the_stick_picks_a_location_scored_with_its_path_and_each_frame_marks_it() -> None:
    plan = compile_plan(load_protocol(LOCATIONS), responses="openxr")
    question = stick_question(plan.protocol.response)
    assert question is not None and question.points == 4
    clock = VirtualClock(10.0)
    source = StickScript([RawInput(SCALE_AXIS, 10.3, 1.0), RawInput(SCALE_AXIS, 10.4, 0.0),
                          RawInput(SCALE_AXIS, 10.6, 0.9), RawInput(SCALE_AXIS, 10.7, 0.1),
                          RawInput(SCALE_CONFIRM, 11.0)])
    drawn: list[PhaseSpec] = []

    def draw(request: FrameRequest, phase: PhaseSpec) -> None:
        drawn.append(phase)

    pacing = PickerPacing(clock, HeadlessDisplay(clock, 90.0), None, True, 1 / 90)
    answer = ask_on_stick({"correct_location": 4}, plan.response, question, source, pacing, 10.0, draw)
    assert (answer.response, answer.correct) == ("4", True) and abs(answer.response_time_s - 1.0) < 1e-9
    path = json.loads(dict(answer.extras)[CHOICE_PATH])
    assert path == [[0.0, 2], [0.3, 3], [0.6, 4]]
    assert all(isinstance(phase, ScreenPhase) for phase in drawn)
    marks = {phase.marker_deg for phase in drawn if isinstance(phase, ScreenPhase)}
    assert marks == {(0.0, 8.0), (8.0, 0.0), (0.0, -8.0)}  # locations 2, 3, 4 of locations_deg
    wrong = ask_on_stick({"correct_location": 1}, plan.response, question,
                         StickScript([RawInput(SCALE_CONFIRM, 12.5)]), pacing, 12.0, draw)
    assert (wrong.response, wrong.correct) == ("2", False)  # confirmed at the start: the middle, location 2


def _changed_centre(image: np.ndarray, base: np.ndarray) -> tuple[float, float]:
    """The mean (row, column) of the pixels where ``image`` differs from ``base``."""
    rows, cols = np.nonzero(np.abs(image - base).max(axis=2) > 0.05)
    assert rows.size > 0
    return float(rows.mean()), float(cols.mean())


def test_the_frame_around_a_highlighted_location_is_drawn_where_the_target_appears() -> None:
    from psyop.rendering.renderer import create_headless_context
    from psyop.session.scene_renderer import SceneRenderer

    plan = compile_plan(load_protocol(LOCATIONS), tracker_ipd_m=0.064)
    schedule = compile_schedule(plan.protocol, 1)
    row = schedule[schedule["correct_location"] == 3].iloc[0].to_dict()  # the disc 8 deg right
    row["contrast_fraction"] = 1.0
    interval = next(phase for phase in plan.phases if phase.show == "stimulus")
    blank = PhaseSpec("blank", 0.0, "blank", "none", primitives=("fixation",))
    ctx = create_headless_context()
    renderer = SceneRenderer(plan, scale=0.25, ctx=ctx, owns_ctx=False)
    try:
        images = {}
        for name, phase in (("target", interval), ("blank", blank), ("empty", ScreenPhase("r", 0.0, "text", "cross", text="Where?")),
                            ("marked", ScreenPhase("r", 0.0, "text", "cross", text="Where?", marker_deg=(8.0, 0.0)))):
            check = renderer.render(row, phase, "conventional", 0.1, (0.0, 0.0, -1.0))
            assert check.ok
            images[name] = renderer._renderer.image("right").copy() if renderer._renderer is not None else None
    finally:
        renderer.close()
        ctx.release()
    assert images["empty"] is not None and images["marked"] is not None
    target = _changed_centre(images["target"], images["blank"])
    frame = _changed_centre(images["marked"], images["empty"])
    width = images["marked"].shape[1]
    # the same place to within 1 % of the view's width (0.9 m against the disc's 1 m: under 0.2 deg apart)
    assert abs(target[0] - frame[0]) < 0.01 * width and abs(target[1] - frame[1]) < 0.01 * width, (target, frame)
    assert frame[1] > width / 2  # right of the centre


def test_a_questionnaire_item_marks_the_point_the_stick_highlights() -> None:
    questionnaire = Questionnaire(name="comfort", when=["end"], items=["Eyes"], scale={"points": 3,
                                                                                     "labels": ["a", "b", "c"]})
    plain = questionnaire_text(questionnaire, 0).splitlines()
    marked = questionnaire_text(questionnaire, 0, 1).splitlines()
    assert plain[-3:] == ["0  a", "1  b", "2  c"] and marked[-3:] == ["0  a", ">  1  b  <", "2  c"]
    assert plain[:-3] == marked[:-3]


def test_the_start_check_lays_out_each_item_with_its_widest_point_marked() -> None:
    from psyop.protocol.session_screens import SessionScreens
    from psyop.session.screens import screen_texts

    labels = ["no", "the longest of the labels", "yes"]
    section = SessionScreens(questionnaires=[Questionnaire(name="comfort", when=["end"], items=["Eyes", "Head"],
                                                           scale={"points": 3, "labels": labels})])
    texts = [text for _, text in screen_texts(section)]
    widest = f">  1  {labels[1]}  <"
    assert sum(widest in text.splitlines() for text in texts) == 2  # one per item, as the controllers show it
    assert sum(f"1  {labels[1]}" in text.splitlines() for text in texts) == 2  # and as shown otherwise
