"""Issue 40 items 3 and 4, follow-ups of the session screens: feedback after trials, questionnaire items answered
live (digit keys, box buttons), the rating scale on the response panel, participant-ended intervals, and the
gallery's full-session example (docs/session_followups.md)."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import pandas as pd
import pytest

from psyop.errors import UserError
from psyop.protocol import load_protocol, parse_protocol
from psyop.run.runner import SessionOptions, run_session
from psyop.schedule import compile_schedule
from psyop.session.clock import VirtualClock
from psyop.session.screens import Moment, ScreenRunner, feedback_text

REPO = Path(__file__).resolve().parents[2]
YES_NO = REPO / "protocols" / "examples" / "yes_no.yaml"
RATING = REPO / "protocols" / "examples" / "rating.yaml"


def _yes_no(tmp_path: Path, session: str, *, repetitions: int = 2, practice: int = 3, phase_s: float | None = None,
            name: str = "yes_no.yaml") -> Path:
    """The yes/no example with fewer trials, ``practice`` practice trials and the ``session:`` section given."""
    text = YES_NO.read_text()
    text = re.sub(r"(?m)^(\s*repetitions:)\s*\d+", rf"\g<1> {repetitions}", text)
    if phase_s is not None:
        text = re.sub(r"(?m)^(\s*(?:-\s*)?(?:duration_s|expected_s):)\s*[\d.]+", rf"\g<1> {phase_s}", text)
    if practice:
        text = text.replace("  randomisation: {kind: full}", f"  randomisation: {{kind: full}}\n  practice_trials: {practice}")
    path = tmp_path / name
    path.write_text(text + textwrap.dedent(session))
    return path


def _run(path: Path, data: Path, participant: str = "S01", **options) -> Path:
    outcome = run_session(load_protocol(path), compile_schedule,
                          SessionOptions(participant=participant, data_root=data, progress=False, fsync=False,
                                         render="cameras", **options))
    assert outcome.status == "complete", outcome.message
    return next(data.glob(f"*/sub-{participant}/ses-1"))


# ---- 1. feedback ---------------------------------------------------------------------------------------------
def test_feedback_follows_each_practice_trial_and_says_whether_it_was_correct(tmp_path: Path) -> None:
    path = _yes_no(tmp_path, "session:\n  feedback: {duration_s: 0.5}\n")
    session = _run(path, tmp_path / "data")
    events = pd.read_parquet(session / "events.parquet")
    trials = pd.read_parquet(session / "trials.parquet").set_index("trial")
    assert list(events["screen"]) == ["feedback"] * 3 and list(events["when"]) == ["practice"] * 3
    assert list(events["after_trial"]) == [0, 1, 2] and trials.loc[[0, 1, 2], "practice"].all()
    assert list(events["text"]) == ["Correct" if c else "Incorrect" for c in trials.loc[[0, 1, 2], "correct"]]
    assert (events["duration_s"] == 0.5).all() and set(events["ended_by"]) == {"timed"}
    for _, event in events.iterrows():  # right after its trial; the next trial starts when it ends
        assert event["start_s"] == trials.loc[event["after_trial"], "trial_end_s"]
        assert trials.loc[event["after_trial"] + 1, "trial_start_s"] == event["end_s"]


def test_feedback_on_main_trials_too_and_its_texts(tmp_path: Path) -> None:
    path = _yes_no(tmp_path, """
        session:
          feedback:
            main: true
            text: {correct: Right!, incorrect: Wrong.}
        """, practice=0)
    session = _run(path, tmp_path / "data")
    events = pd.read_parquet(session / "events.parquet")
    trials = pd.read_parquet(session / "trials.parquet")
    assert len(events) == len(trials) == 10 and set(events["when"]) == {"main"}
    assert list(events["text"]) == ["Right!" if c else "Wrong." for c in trials.sort_values("trial")["correct"]]
    assert (events["duration_s"] == 1.0).all()  # the default duration_s


def test_feedback_for_a_kind_without_a_correct_answer_shows_the_answer_and_a_timeout_its_own_text() -> None:
    protocol = parse_protocol(YES_NO.read_text() + "session:\n  feedback: {text: {answer: 'You chose {answer}.'}}\n",
                              "study.yaml")
    feedback = protocol.session.feedback
    assert feedback_text(feedback, {"correct": None, "response": "4"}) == "You chose 4."
    assert feedback_text(feedback, {"correct": None, "response": "timeout"}) == "No answer in time"
    assert feedback_text(feedback, {"correct": False, "response": "yes"}) == "Incorrect"


def test_a_rating_session_gets_its_answers_as_feedback(tmp_path: Path) -> None:
    text = re.sub(r"(?m)^(\s*repetitions:)\s*\d+", r"\g<1> 1", RATING.read_text())
    path = tmp_path / "rating.yaml"
    path.write_text(text + "session:\n  feedback: {main: true, duration_s: 0.25}\n")
    session = _run(path, tmp_path / "data")
    events = pd.read_parquet(session / "events.parquet")
    trials = pd.read_parquet(session / "trials.parquet").set_index("trial")
    assert trials["correct"].isna().all() and len(events) == len(trials)
    assert list(events["text"]) == [f"Your answer: {trials.loc[t, 'response']}" for t in events["after_trial"]]


@pytest.mark.parametrize(("feedback", "message"), [
    ("{text: {answer: 'You said {value}'}}", "unknown placeholder"),
    ("{duration_s: 0}", "greater than 0"),
    ("{practice: maybe}", "valid boolean"),
    ("{after: all}", "after"),
])
def test_bad_feedback_is_refused_with_its_line(feedback: str, message: str) -> None:
    text = YES_NO.read_text() + f"session:\n  feedback: {feedback}\n"
    line = text.count("\n")
    with pytest.raises(UserError, match=message) as error:
        parse_protocol(text, "study.yaml")
    assert f"study.yaml:{line}" in str(error.value)


# ---- 2. questionnaire items answered live ----------------------------------------------------------------------
class _ScriptedKeys:
    """A keyboard's event source that types the next scripted keys at each poll (None: nothing)."""

    def __init__(self, clock: VirtualClock, script: list[tuple[str, ...] | None]) -> None:
        self.clock, self.script, self.polls = clock, iter(script), 0

    def poll(self) -> list[tuple[str, float]]:
        self.polls += 1
        keys = next(self.script, None) or ()
        return [(key, self.clock.now_s()) for key in keys]


class _Recorder:
    def __init__(self) -> None:
        self.events: list[dict] = []
        self.answers: list[dict] = []

    def append_event(self, row) -> None:
        self.events.append(dict(row))

    def append_answers(self, rows) -> None:
        self.answers += [dict(r) for r in rows]

    def close(self) -> None:
        pass


def _host(clock: VirtualClock) -> SimpleNamespace:
    gaze = SimpleNamespace(set_plan=lambda plan: None, drain_raw=lambda: [], latest=lambda now: None)
    return SimpleNamespace(identity={"study": "yes_no_detection", "participant": "L1", "session": 1}, clock=clock,
                           gaze=gaze, renderer=None, display=SimpleNamespace(wait_until_ready=lambda: None),
                           store=SimpleNamespace(run_index=0, keeps_samples=False),
                           config=SimpleNamespace(every_frame=False), frame_period_s=1 / 90, events=())


def test_a_live_participant_rates_ssq_items_with_digit_keys() -> None:
    """Raw keys while an item shows: the digits 0..3 (top row or keypad) answer it; the kind's answer keys, digits
    beyond the scale and keys held over from before the item do not."""
    from psyop.devices.responses.keyboard import KeyboardResponses
    from psyop.protocol.kinds import kind_of

    protocol = parse_protocol(YES_NO.read_text() + "session:\n  questionnaires: [{name: ssq, when: end}]\n",
                              "study.yaml")
    clock = VirtualClock()
    script: list[tuple[str, ...] | None] = [None] * 20 + [("y", "7", "2")] + [None, ("left",), ("kp_3",)]
    script += [("1",)] * 14
    keys = _ScriptedKeys(clock, script)
    source = KeyboardResponses(keys, kind_of(protocol.response))
    recorder = _Recorder()
    runner = ScreenRunner(protocol.session, "live", 1, recorder, True,
                          lambda row, now: (r.response if (r := source.collect(row, now)) else None), source.poll_raw)
    runner._administer(_host(clock), protocol.session.questionnaires[0], Moment("end", -1, 0, 3, 3), {"trial": 2})
    answers = [a["answer"] for a in recorder.answers]
    assert answers == [2, 3] + [1] * 14
    assert recorder.answers[0]["answered_by"] == "input:2" and recorder.answers[1]["answer_label"] == "severe"
    assert recorder.events[0]["duration_s"] == pytest.approx(0.20, abs=0.015)  # 20 empty polls 10 ms apart
    assert keys.polls == 20 + 4 + 14


def test_a_response_box_rates_items_with_its_digit_buttons_and_still_answers_trials() -> None:
    from psyop.devices.responses.serial_box import SerialResponseBox
    from psyop.protocol.kinds import kind_named

    box = SerialResponseBox.__new__(SerialResponseBox)  # the line handling only, without a serial port
    import queue

    box.buttons, box.kind, box._presses, box._prompt_s = dict(kind_named("two_interval").buttons), \
        kind_named("two_interval"), queue.Queue(), 0.0
    box._reader = SimpleNamespace(error=None)
    for line in ("B0", "B3", "B2", "BX", "B12"):
        box._on_line(line, 1.0)
    assert box.poll_raw() == [("0", 1.0, None), ("3", 1.0, None), ("2", 1.0, "2")]
    for line in ("B0", "B1"):
        box._on_line(line, 2.0)
    response = box.collect({"correct_interval": 1}, 2.5)  # B0 answers nothing of two_interval: skipped
    assert response is not None and response.response == "1" and response.correct is True


WINDOW_SCRIPT = textwrap.dedent(
    """
    from pathlib import Path
    from psyop.protocol import load_protocol
    from psyop.schedule import compile_schedule
    from psyop.run.runner import SessionOptions, run_session
    import psyop.devices.window as window

    typed = window.GlfwWindow.poll
    count = [0]
    def poll(self):  # a participant who answers 'y' and types the digit 0..3 by turns whenever asked
        self.inject_key("y")
        self.inject_key(str(count[0] % 4))
        count[0] += 1
        return typed(self)
    window.GlfwWindow.poll = poll
    outcome = run_session(load_protocol(Path({protocol!r})), compile_schedule, SessionOptions(
        participant="W1", data_root=Path({data!r}), clock="real", display="window", responses="keyboard",
        tracker="sim", progress=False, render="auto", window_scale=0.2))
    print(outcome.status)
    """
)


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs xvfb-run (Debian xvfb)")
def test_a_window_session_answers_the_ssq_with_typed_digits_under_xvfb(tmp_path: Path) -> None:
    path = _yes_no(tmp_path, "session:\n  questionnaires: [{name: ssq, when: [start, end]}]\n", repetitions=1,
                   practice=0, phase_s=0.03)
    script = WINDOW_SCRIPT.format(protocol=str(path), data=str(tmp_path / "data"))
    result = subprocess.run(["xvfb-run", "-a", sys.executable, "-c", script], capture_output=True, text=True,
                            timeout=180)
    assert result.returncode == 0 and result.stdout.split()[-1] == "complete", result.stderr[-2000:]
    session = tmp_path / "data" / "yes_no_detection" / "sub-W1" / "ses-1"
    answers = pd.read_parquet(session / "questionnaires.parquet")
    assert list(answers.groupby("administration")["item"].count()) == [16, 16]
    assert answers["answer"].notna().all() and answers["answer"].between(0, 3).all()
    assert (answers["answered_by"] == "input:" + answers["answer"].astype(str)).all()
    assert answers["answer"].nunique() > 1
    trials = pd.read_parquet(session / "trials.parquet")
    assert (trials["response"] == "yes").all()


# ---- 3. the rating scale on the response panel ----------------------------------------------------------------
def test_the_rating_kind_shows_its_scale_under_the_prompt_and_other_kinds_keep_their_panel() -> None:
    from psyop.rendering.text import wrapped_lines
    from psyop.session.plan import compile_plan

    rating = compile_plan(load_protocol(RATING)).response
    prompt = rating.prompt or rating.question
    assert rating.keeps_lines and rating.participant_text is not None
    lines = rating.participant_text.split("\n")
    assert lines[0] == prompt.strip() and lines[1] == "" and lines[2:] == [
        "1  not at all realistic", "2  hardly realistic", "3  slightly realistic", "4  moderately realistic",
        "5  quite realistic", "6  very realistic", "7  completely realistic"]
    assert len(wrapped_lines(rating.participant_text, keep_lines=True)) <= 16
    assert rating.as_dict()["response_text"] == "\n".join(lines[2:])
    from psyop.protocol.kinds.rating import KIND, RatingResponse

    section = RatingResponse.model_validate({"kind": "rating", "stimulus": {"mode": "ocular"}, "scale": {"points": 5}})
    assert KIND.response_text(section) == "1 (lowest) to 5 (highest)"  # labels are optional
    yes_no = compile_plan(load_protocol(YES_NO)).response
    assert not yes_no.keeps_lines and yes_no.response_text is None
    assert yes_no.participant_text == yes_no.prompt.strip() and "response_text" not in yes_no.as_dict()


# ---- 4. participant-ended intervals -------------------------------------------------------------------------------
class _TimedKeys:
    """Key presses at set times on the session clock, each delivered by the first poll at or after it."""

    def __init__(self, clock: VirtualClock, presses: list[tuple[str, float]]) -> None:
        self.clock, self.presses = clock, list(presses)

    def poll(self) -> list[tuple[str, float]]:
        due = [p for p in self.presses if p[1] <= self.clock.now_s() + 1e-12]
        self.presses = [p for p in self.presses if p not in due]
        return due


def _paced_loop(tmp_path: Path, source_for):
    """A trial loop on the virtual clock and the headless display, every frame drawn (no renderer), over the yes/no
    example whose interval is participant-paced (min_duration_s 0.5, expected_s 2)."""
    from psyop.session.frames import HeadlessDisplay
    from psyop.session.loop import LoopConfig, LoopFacts, LoopOptions, TrialLoop
    from psyop.session.plan import compile_plan

    text = YES_NO.read_text().replace("      duration_s: 2                     # Sec. 5.1: 2-second intervals",
                                      "      min_duration_s: 0.5\n      expected_s: 2")
    assert "min_duration_s" in text
    path = tmp_path / "paced.yaml"
    path.write_text(text)
    protocol = load_protocol(path)
    plan = compile_plan(protocol)
    interval = plan.phases[1]
    assert interval.name == "interval1" and interval.duration_s == 0.5 and interval.ends_after_s == 0.5
    assert "ends_after_s" not in plan.metadata()["phases"][1]  # session.json's phases as before (protocol_text has it)
    clock = VirtualClock()
    gaze = SimpleNamespace(set_plan=lambda p: None, drain_raw=lambda: [], latest=lambda now: None)
    config = LoopConfig.of(LoopFacts.of_plan(plan), LoopOptions(every_frame=True, progress=False))
    loop = TrialLoop(identity={"study": plan.study, "participant": "L1", "session": 1}, phases=plan.phases,
                     clock=clock, gaze=gaze, responses=source_for(clock, plan), renderer=None,
                     display=HeadlessDisplay(clock, 90.0), store=SimpleNamespace(run_index=0), config=config,
                     response=plan.response)
    row = compile_schedule(protocol, 1).to_dict("records")[0]
    return loop, row


def test_a_live_participant_ends_a_paced_interval_after_its_minimum(tmp_path: Path) -> None:
    from psyop.devices.responses.keyboard import KeyboardResponses

    sources = []

    def keyboard(clock, plan):  # y during the minimum (dropped), n at 2.3 s ends the interval, y answers at 2.6 s
        sources.append(KeyboardResponses(_TimedKeys(clock, [("y", 1.2), ("n", 2.3), ("y", 2.6)]), plan.kind,
                                         keymap=plan.response.inputs.keys))
        return sources[0]

    loop, row = _paced_loop(tmp_path, keyboard)
    record, frames = loop.run_trial(row)
    assert record["interval1_onset_s"] == pytest.approx(1.0)
    assert record["interval1_duration_s"] == pytest.approx(1.3, abs=1.5 / 90)  # 1.0 + 0.5 minimum .. the n at 2.3
    assert record["response"] == "yes" and record["response_time_s"] == pytest.approx(0.3, abs=1.5 / 90)
    assert sources[0].early_presses == 1  # the y pressed during the minimum
    table = frames.table().to_pandas()
    assert (table["phase"] == "interval1").sum() == pytest.approx(1.3 * 90, abs=2)


def test_a_source_without_raw_input_ends_a_paced_interval_at_its_minimum(tmp_path: Path) -> None:
    from psyop.session.responses.base import Response

    class Simulated:  # answers at once, as the simulated observer does; no raw input
        needs_images = False

        def collect(self, row, now_s):
            return Response("no", correct=None, response_time_s=0.0)

        def timed_out(self):
            pass

        def close(self):
            pass

    loop, row = _paced_loop(tmp_path, lambda clock, plan: Simulated())
    record, _ = loop.run_trial(row)
    assert record["interval1_duration_s"] == pytest.approx(0.5, abs=1e-9)
    assert record["trial_end_s"] == pytest.approx(1.5, abs=1.5 / 90)


# ---- 5. the gallery's full-session example ------------------------------------------------------------------------
def test_the_full_session_example_runs_every_screen_in_order_for_two_participants(tmp_path: Path) -> None:
    path = REPO / "protocols" / "examples" / "full_session.yaml"
    for participant in ("S01", "S02"):
        session = _run(path, tmp_path / "data", participant)
        events = pd.read_parquet(session / "events.parquet")
        trials = pd.read_parquet(session / "trials.parquet")
        answers = pd.read_parquet(session / "questionnaires.parquet")
        got = list(events[["screen", "when"]].itertuples(index=False, name=None))
        expected = ([("instructions", "start")] * 3 + [("questionnaire", "start")] * 16
                    + [("feedback", "practice")] * 4 + [("break", "between_blocks")] * 2
                    + [("questionnaire", "end")] * 16 + [("end", "end")])
        assert got == expected, participant
        feedback = events[events["screen"] == "feedback"]
        practice = trials[trials["practice"]].set_index("trial")
        assert list(feedback["after_trial"]) == sorted(practice.index)
        assert list(feedback["text"]) == ["Correct" if practice.loc[t, "correct"] else "Incorrect"
                                          for t in feedback["after_trial"]]
        breaks = events[events["screen"] == "break"]
        assert list(breaks["trials_done"]) == [4, 14]  # practice -> block 0, block 0 -> block 1
        assert list(answers.groupby("administration")["item"].count()) == [16, 16]
        assert answers["answer"].notna().all() and len(trials) == 24
