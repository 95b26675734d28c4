"""The screens around a session's trials (the protocol's ``session:``, psyop.protocol.session_screens).

The loop asks :class:`ScreenRunner` before each trial and once after the last:

- before the run's first trial: the ``instructions`` pages, then each questionnaire whose ``when`` has
  ``start`` (only in a session with no trial recorded yet: a resumed run shows the instructions again but
  does not ask the start questionnaires a second time);
- before a later trial: a ``breaks`` screen when ``every_trials`` more trials have been recorded since the
  last one, or the block changed and ``between_blocks`` is true (one break when both hold); then, when the
  block changed, the ``between_blocks`` questionnaires and, for a block listed in ``at_blocks``, the
  instructions again;
- after the last trial (the run ran out of trials, not stopped): the ``end`` questionnaires, then the
  ``end_screen``.

Each screen is a head-fixed text panel (:class:`ScreenPhase`, drawn by psyop.session.scene_renderer through
the response prompt's text path, mono and stereo); a questionnaire shows one item per screen with its scale.
Each screen is participant-paced:

- a simulated participant (``--responses sim``) ends it after the screen's ``expected_s`` on the session clock
  (a questionnaire item after ``item_expected_s``) and answers each item from the protocol's
  ``simulated_answers`` (a severity drawn once per participant, seeded by the session's seed, plus per-item
  noise; every draw keyed by the questionnaire, its time and the item, so a resumed session draws the same);
- nobody (``--responses none``) lets it pass after the same time, answering nothing;
- a live participant ends it with the next input the session's response source accepts as an answer (the
  response kind's keys on the keyboard, its buttons on a response box or a headset controller; "any key" means
  any answer key). A questionnaire item is answered with a scale point: the digit keys 0 .. points - 1 (top row
  or keypad) or the response box's digit buttons, read raw from a source that offers them (``poll_raw``: the
  keyboard, the response box) and interpreted here; any other input leaves the item showing. The headset's
  controllers pick the point with a stick, as on a rating's scale (``scale_input``: the controllers read through
  :data:`~psyop.protocol.kinds.confidence.SCALE_CONTROLLER`, psyop.session.scale_picker): the item's scale is drawn
  with the highlighted point marked (``>  1  slight  <``, starting at the scale's middle), a sideways flick moves
  it one point, either select button confirms it; ``answered_by`` is ``controllers:POINT``.
- feedback after a trial (``feedback``) is timed, not participant-paced: it shows for its ``duration_s``
  whoever answers (``ended_by`` ``timed``).

Every screen shown is one record in the run's events log and every item answered one record in its
questionnaire log (psyop.session.log.screens_log), durable when it ends; finalisation writes events.parquet
and questionnaires.parquet. Each screen's onset is also a ``phase`` event (trial -1, condition
``session_screen``) for the session's outside recorders (psyop.session.events). A session without
``session:`` runs exactly as before: the loop never calls this module.
"""

from __future__ import annotations

import dataclasses
import math
import zlib
from pathlib import Path
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, Protocol

import numpy as np

from psyop.protocol import ssq
from psyop.datacontract import TIMEOUT_RESPONSE
from psyop.rendering.text import Picture
from psyop.protocol.session_screens import Feedback, Questionnaire, SessionScreens as ScreensSection
from psyop.session.events import SessionEvent
from psyop.session.gaze.plan import FixationPlan
from psyop.session.log.raw_gaze import raw_gaze_table
from psyop.session.phases import PhaseSpec
from psyop.session.rows import JsonMapping, JsonObject, TrialRow
from psyop.session.scale_picker import MappedRawSource, PickerPacing, ScalePicker, run_picker

if TYPE_CHECKING:
    from psyop.session.plan import SessionPlan
    from psyop.session.clock import Clock
    from psyop.session.events import EventSink
    from psyop.session.frames import Display, DisplayInterrupted, FrameRenderer, FrameRequest
    from psyop.session.gaze.sample import GazeSource
    from psyop.session.log.screens_log import ScreenRecorder
    from psyop.session.log.store import SessionLog

#: who ends the screens: the simulated participant, nobody (pass after expected_s), or a live participant
Pacing = Literal["simulated", "nobody", "live"]
#: a live participant's input: (the row the response source scores against, now) -> the answer given, or None
ScreenInput = Callable[[TrialRow, float], "str | None"]
#: a live source's raw input since the last poll: (input name, time on the session clock, the kind's answer or None)
RawInput = Callable[[], "list[tuple[str, float, str | None]]"]
#: the row a screen's frames are drawn and logged with (no trial)
SCREEN_ROW: JsonObject = {"trial": -1, "condition": "session_screen"}


@dataclass(frozen=True)
class ScreenPhase(PhaseSpec):
    """A phase showing a session screen: ``text`` on a head-fixed panel (``show`` 'text'), its line breaks kept,
    under ``image`` (an instruction page's picture: its path relative to the protocol, ``image_width_deg`` wide,
    None: as wide as fits; psyop.rendering.text.picture_page)."""

    text: str = ""
    image: str | None = None
    image_width_deg: float | None = None
    #: a location to mark in front of the panel (Fick [azimuth, elevation] deg: the n_afc location the controllers'
    #: stick highlights, psyop.session.choice_marker); None: the panel alone
    marker_deg: tuple[float, float] | None = None


@dataclass(frozen=True)
class Screen:
    """One screen: ``screen`` (instructions | break | questionnaire | end), ``name`` (the questionnaire's, else
    the screen's), ``page`` (page or item, from 0) of ``n_pages``, its text and how long a simulated participant
    takes; a questionnaire item also has its ``questionnaire``."""

    screen: str
    name: str
    page: int
    n_pages: int
    text: str
    expected_s: float
    questionnaire: Questionnaire | None = None
    #: shown for ``expected_s`` whoever participates, never ended by an input (feedback)
    timed: bool = False
    #: an instruction page's picture above the text (its path relative to the protocol) and width (None: fits)
    image: str | None = None
    image_width_deg: float | None = None

    def phase(self) -> ScreenPhase:
        return ScreenPhase(f"{self.screen}_{self.page}", self.expected_s, "text", "cross", text=self.text,
                           image=self.image, image_width_deg=self.image_width_deg)


@dataclass(frozen=True)
class Moment:
    """Where in the session a screen is shown: ``when`` (start | every_trials | between_blocks | at_block | end),
    the trial it comes before (-1: the end), the block and the trials recorded / left of ``total``."""

    when: str
    before_trial: int
    block: int
    done: int
    total: int
    after_trial: int = -1  # the trial a feedback screen follows (-1: every other screen)

    @property
    def left(self) -> int:
        return max(0, self.total - self.done)


# ---- what each screen says ---------------------------------------------------------------------------
def item_texts(questionnaire: Questionnaire) -> tuple[str, ...]:
    """The statements a questionnaire's items rate: its ``items``, or the SSQ's 16 symptoms (psyop.protocol.ssq)."""
    return ssq.item_texts() if questionnaire.name == ssq.NAME else tuple(questionnaire.items or ())


def scale_labels(questionnaire: Questionnaire) -> tuple[str, ...]:
    """Its ``scale``'s labels (lowest first), or the SSQ's none / slight / moderate / severe."""
    if questionnaire.name == ssq.NAME:
        return ssq.SCALE_LABELS
    assert questionnaire.scale is not None  # validated: a questionnaire other than ssq has a scale
    assert len(questionnaire.scale.labels) == questionnaire.scale.points
    return tuple(questionnaire.scale.labels)


def questionnaire_text(questionnaire: Questionnaire, index: int, marked: int | None = None) -> str:
    """Item ``index``'s screen: the title, the item's number, the item, then the scale's points and labels, with
    point ``marked`` (0 .. points - 1: the one the controllers' stick highlights) between ``>`` and ``<``."""
    items, labels = item_texts(questionnaire), scale_labels(questionnaire)
    title = questionnaire.title or (ssq.TITLE if questionnaire.name == ssq.NAME else questionnaire.name)
    scale = "\n".join((f">  {point}  {label}  <" if point == marked else f"{point}  {label}") if marked is not None
                      else f"{point}  {label}" for point, label in enumerate(labels))
    return f"{title}\nitem {index + 1} of {len(items)}\n\n{items[index]}\n\n{scale}"


def questionnaire_screens(questionnaire: Questionnaire) -> list[Screen]:
    """One screen per item (:func:`questionnaire_text`)."""
    items = item_texts(questionnaire)
    return [Screen("questionnaire", questionnaire.name, index, len(items), questionnaire_text(questionnaire, index),
                   float(questionnaire.item_expected_s), questionnaire)
            for index in range(len(items))]


def instruction_screens(section: ScreensSection) -> list[Screen]:
    pages = section.instructions.pages if section.instructions is not None else []
    return [Screen("instructions", "instructions", i, len(pages), page.text, float(page.expected_s), image=page.image,
                   image_width_deg=None if page.image_width_deg is None else float(page.image_width_deg))
            for i, page in enumerate(pages)]


def instruction_picture(section: ScreensSection | None, page: int, base_dir: Path) -> Picture | None:
    """The picture of instruction page ``page`` (its file under ``base_dir``, the protocol's folder), or None."""
    pages = section.instructions.pages if section is not None and section.instructions is not None else []
    if not 0 <= page < len(pages) or pages[page].image is None:
        return None
    width = pages[page].image_width_deg
    return Picture(str(base_dir / str(pages[page].image)), None if width is None else float(width))


def page_pictures(plan: "SessionPlan") -> list[tuple[tuple[str | int, ...], str, Picture]]:
    """Every instruction page with an image: its protocol path (its ``image_width_deg``, else its ``image``), its
    text and its :class:`~psyop.rendering.text.Picture` (the file relative to the protocol)."""
    section = plan.protocol.session
    pages = section.instructions.pages if section is not None and section.instructions is not None else []
    base = Path(plan.protocol.source_name).parent if plan.protocol.source_name else Path(".")
    out: list[tuple[tuple[str | int, ...], str, Picture]] = []
    for i, page in enumerate(pages):
        picture = instruction_picture(section, i, base)
        if picture is not None:
            key = "image" if page.image_width_deg is None else "image_width_deg"
            out.append((("session", "instructions", "pages", i, key), page.text, picture))
    return out


def break_screen(section: ScreensSection, moment: Moment) -> Screen:
    breaks = section.breaks
    assert breaks is not None
    text = breaks.text.format(done=moment.done, left=moment.left, total=moment.total)
    return Screen("break", "break", 0, 1, text, float(breaks.expected_s))


def feedback_text(feedback: Feedback, record: TrialRow) -> str:
    """What the feedback after trial ``record`` says: correct / incorrect when its kind scored the answer, the
    timeout text when nobody answered in time, else the answer given (a kind with no correct answer)."""
    correct, response = record.get("correct"), str(record.get("response"))
    if correct is not None and not (isinstance(correct, float) and math.isnan(correct)):
        return feedback.text.correct if bool(correct) else feedback.text.incorrect
    if response == TIMEOUT_RESPONSE:
        return feedback.text.timeout
    return feedback.text.answer.format(answer=response)


def feedback_screen(feedback: Feedback, record: TrialRow) -> Screen:
    return Screen("feedback", "feedback", 0, 1, feedback_text(feedback, record), float(feedback.duration_s),
                  timed=True)


def end_screens(section: ScreensSection) -> list[Screen]:
    end = section.end_screen
    return [] if end is None else [Screen("end", "end", 0, 1, end.text, float(end.expected_s))]


def screens_of_kind(section: ScreensSection, kind: str, *, done: int = 0, total: int = 0) -> list[Screen]:
    """Every screen of ``kind`` (instructions | break | questionnaire | end | feedback) in session order (a break as after
    ``done`` of ``total`` trials): what ``psyop render --phase KIND --screen N`` draws."""
    if kind == "instructions":
        return instruction_screens(section)
    if kind == "break":
        return [] if section.breaks is None else [break_screen(section, Moment("break", 0, 0, done, total))]
    if kind == "questionnaire":
        return [s for q in section.questionnaires for s in questionnaire_screens(q)]
    if kind == "end":
        return end_screens(section)
    if kind == "feedback":  # after a correct answer, then after an incorrect one
        return [] if section.feedback is None else [feedback_screen(section.feedback, {"correct": c})
                                                    for c in (True, False)]
    raise ValueError(f"unknown screen kind {kind!r}")


#: the trial counts a break's text is checked with before the session (as wide as any count a session reaches)
WIDEST_BREAK_COUNT = 99999


def screen_texts(section: ScreensSection) -> list[tuple[tuple[str | int, ...], str]]:
    """Every text a screen of ``section`` can show, with the protocol path it is written at (a break's with
    :data:`WIDEST_BREAK_COUNT` trials, an answer's feedback with a six-decimal answer, a questionnaire item also
    with its widest scale point marked as the controllers mark it): what a display checks
    for room before the session (psyop.session.text_fit)."""
    out: list[tuple[tuple[str | int, ...], str]] = [(("session", "instructions", "pages", s.page, "text"), s.text)
                                                    for s in instruction_screens(section)]
    if section.breaks is not None:
        count = WIDEST_BREAK_COUNT
        moment = Moment("break", 0, 0, count, count * 2)
        out.append((("session", "breaks", "text"), break_screen(section, moment).text))
    for index, questionnaire in enumerate(section.questionnaires):
        path: tuple[str | int, ...] = ("session", "questionnaires", index)
        labels = scale_labels(questionnaire)
        widest = max(range(len(labels)), key=lambda point: len(f"{point}  {labels[point]}"))
        for s in questionnaire_screens(questionnaire):  # as shown, and with the widest point marked (controllers)
            at = path + (("items", s.page) if questionnaire.items else ())
            out += [(at, s.text), (at, questionnaire_text(questionnaire, s.page, marked=widest))]
    out += [(("session", "end_screen", "text"), s.text) for s in end_screens(section)]
    feedback = section.feedback
    if feedback is not None:
        out += [(("session", "feedback", "text", name), text) for name, text in (
            ("correct", feedback.text.correct), ("incorrect", feedback.text.incorrect),
            ("timeout", feedback.text.timeout), ("answer", feedback.text.answer.format(answer="0.000000")))]
    return out


# ---- the simulated participant's answers ----------------------------------------------------------------
def _key(text: str) -> int:
    return zlib.crc32(text.encode())


@dataclass(frozen=True)
class SimulatedAnswerer:
    """Answers from ``simulated_answers``: severity ~ N(severity_mean, severity_sd) clipped to [0, 1], drawn
    once from the session ``seed``; an item's answer round(severity x (points - 1) + N(0, item_sd)) clipped to
    the scale, drawn from its own stream keyed by (seed, questionnaire, when, the trial it precedes, item)."""

    seed: int
    severity_mean: float
    severity_sd: float
    item_sd: float

    @property
    def severity(self) -> float:
        rng = np.random.default_rng([self.seed, _key("questionnaire_severity")])
        return float(np.clip(self.severity_mean + self.severity_sd * rng.standard_normal(), 0.0, 1.0))

    def answer(self, questionnaire: str, moment: Moment, item: int, points: int) -> int:
        rng = np.random.default_rng([self.seed, _key(questionnaire), _key(moment.when), moment.before_trial + 1,
                                     item])
        value = self.severity * (points - 1) + self.item_sd * rng.standard_normal()
        return int(np.clip(np.rint(value), 0, points - 1))


# ---- showing screens -------------------------------------------------------------------------------------
class _Regime(Protocol):
    @property
    def every_frame(self) -> bool: ...


class ScreenHost(Protocol):
    """What the screens use of the trial loop (psyop.session.loop.TrialLoop), read only."""

    @property
    def identity(self) -> JsonObject: ...
    @property
    def clock(self) -> Clock: ...
    @property
    def gaze(self) -> GazeSource: ...
    @property
    def renderer(self) -> FrameRenderer | None: ...
    @property
    def display(self) -> Display: ...
    @property
    def store(self) -> SessionLog: ...
    @property
    def config(self) -> _Regime: ...
    @property
    def frame_period_s(self) -> float: ...
    @property
    def events(self) -> tuple[EventSink, ...]: ...
    def note_display_interruption(self, trial: int, exc: DisplayInterrupted) -> None: ...


@dataclass
class ScreenRunner:
    """Runs the protocol's ``session:`` screens for one run of the loop (see the module docstring); ``recorder``
    keeps them (None: a log that keeps nothing of them), ``fresh``: no trial of the session is recorded yet."""

    section: ScreensSection
    pacing: Pacing
    seed: int
    recorder: ScreenRecorder | None = None
    fresh: bool = True
    live_input: ScreenInput | None = None
    raw_input: RawInput | None = None  # a live source's raw input: questionnaire items answered with digits
    scale_input: MappedRawSource | None = None  # the controllers read as a scale: questionnaire items picked with a stick
    _block: int | None = None
    _break_mark: int = 0
    _administrations: int = 0

    @property
    def answerer(self) -> SimulatedAnswerer:
        a = self.section.simulated_answers
        return SimulatedAnswerer(int(self.seed), float(a.severity_mean), float(a.severity_sd), float(a.item_sd))

    def close(self) -> None:
        if self.recorder is not None:
            self.recorder.close()

    def before_trial(self, loop: ScreenHost, row: TrialRow, done: int, total: int) -> None:
        """The screens due before trial ``row`` (``done`` of ``total`` trials recorded)."""
        block = int(row.get("block", 0))
        previous, self._block = self._block, block
        trial = int(row["trial"])
        every = self.section.breaks.every_trials if self.section.breaks is not None else None
        if previous is None:  # the run's first trial
            self._break_mark = done // every if every else 0
            self._show_all(loop, instruction_screens(self.section), Moment("start", trial, block, done, total), row)
            if self.fresh:
                self._questionnaires(loop, "start", Moment("start", trial, block, done, total), row)
            return
        changed = block != previous
        breaks = self.section.breaks
        periodic = every is not None and done // every > self._break_mark
        if every is not None:
            self._break_mark = done // every
        if breaks is not None and (periodic or (changed and breaks.between_blocks)):
            moment = Moment("between_blocks" if changed and breaks.between_blocks else "every_trials", trial, block,
                            done, total)
            self._show_all(loop, [break_screen(self.section, moment)], moment, row)
        if changed:
            self._questionnaires(loop, "between_blocks", Moment("between_blocks", trial, block, done, total), row)
            instructions = self.section.instructions
            if instructions is not None and block in instructions.at_blocks:
                self._show_all(loop, instruction_screens(self.section), Moment("at_block", trial, block, done, total),
                               row)

    def after_trial(self, loop: ScreenHost, record: TrialRow, done: int, total: int) -> None:
        """The feedback after trial ``record`` (just recorded; ``done`` of ``total`` trials recorded), when the
        protocol's ``feedback`` is on for its kind of trial (``practice`` or ``main``)."""
        feedback = self.section.feedback
        practice = bool(record.get("practice", False))
        if feedback is None or not (feedback.practice if practice else feedback.main):
            return
        moment = Moment("practice" if practice else "main", -1, int(record.get("block", 0)), done, total,
                        after_trial=int(record["trial"]))
        self._show(loop, feedback_screen(feedback, record), moment, record)

    def at_end(self, loop: ScreenHost, done: int, total: int, row: TrialRow) -> None:
        """After the run's last trial: the end questionnaires, then the end screen (``row``: the last trial's,
        which a live participant's response source scores its input against)."""
        moment = Moment("end", -1, int(row.get("block", 0)), done, total)
        self._questionnaires(loop, "end", moment, row)
        self._show_all(loop, end_screens(self.section), moment, row)

    def _questionnaires(self, loop: ScreenHost, when: str, moment: Moment, row: TrialRow) -> None:
        for questionnaire in self.section.questionnaires:
            if when in questionnaire.when:
                self._administer(loop, questionnaire, moment, row)

    def _administer(self, loop: ScreenHost, questionnaire: Questionnaire, moment: Moment, row: TrialRow) -> None:
        """Each item on its own screen; each answer durable when its screen ends."""
        self._administrations += 1
        labels = scale_labels(questionnaire)
        for screen in questionnaire_screens(questionnaire):
            start, end, ended_by = self._show(loop, screen, moment, row)
            answer, by = self._answer(questionnaire.name, moment, screen.page, len(labels), ended_by)
            if self.recorder is not None:
                self.recorder.append_answers([{
                    "run": loop.store.run_index, "study": str(loop.identity.get("study")),
                    "participant": str(loop.identity.get("participant")),
                    "session": int(loop.identity.get("session", 0)), "questionnaire": questionnaire.name,
                    "administration": self._administrations, "when": moment.when,
                    "before_trial": moment.before_trial, "item": screen.page,
                    "item_text": item_texts(questionnaire)[screen.page], "answer": answer,
                    "answer_label": None if answer is None else labels[answer], "scale_points": len(labels),
                    "answered_by": by, "start_s": start, "end_s": end}])

    def _answer(self, name: str, moment: Moment, item: int, points: int, ended_by: str) -> tuple[int | None, str]:
        """The item's answer and who gave it (a live input counts only when it is a scale point)."""
        if self.pacing == "simulated":
            return self.answerer.answer(name, moment, item, points), "simulated"
        if self.pacing == "live":
            source, _, given = ended_by.partition(":")
            if source in ("input", "controllers") and given.isdigit() and int(given) < points:
                return int(given), ended_by
            return None, ended_by
        return None, ended_by

    def _given(self, screen: Screen, row: TrialRow, start: float, now_s: float) -> str | None:
        """A live participant's input that ends ``screen`` (shown since ``start``), or None: on a questionnaire
        item a scale point read raw (when the source offers raw input), else the next answer input."""
        if screen.questionnaire is not None and self.raw_input is not None:
            points = len(scale_labels(screen.questionnaire))
            for name, t_s, _ in self.raw_input():
                point = scale_point(name, points)
                if point is not None and t_s >= start:  # a key held over from the item before is not this answer
                    return str(point)
            return None
        return self.live_input(row, now_s) if self.live_input is not None else None

    def _show_all(self, loop: ScreenHost, screens: list[Screen], moment: Moment, row: TrialRow) -> None:
        for screen in screens:
            self._show(loop, screen, moment, row)

    def _show(self, loop: ScreenHost, screen: Screen, moment: Moment, row: TrialRow) -> tuple[float, float, str]:
        """Show ``screen`` until the participant ends it (once the display can show it; a display interruption
        shows it again, or ends the session); record it. (start_s, end_s, what ended it)."""
        from psyop.session.frames import DisplayInterrupted

        while True:
            loop.display.wait_until_ready()
            try:
                start, end, ended_by = self._hold(loop, screen, row)
                break
            except DisplayInterrupted as exc:
                loop.note_display_interruption(-1, exc)
                if not exc.rerun:
                    raise
        samples = raw_gaze_table(loop.gaze.drain_raw(), run=loop.store.run_index, trial=-1)
        if loop.store.keeps_samples:  # the tracker's samples while the screen showed (trial -1, like validations)
            loop.store.append_gaze(samples, key=-1)
        if self.recorder is not None:
            self.recorder.append_event(event_row(loop.store.run_index, screen, moment, start, end, ended_by))
        return start, end, ended_by

    def _hold(self, loop: ScreenHost, screen: Screen, row: TrialRow) -> tuple[float, float, str]:
        """Draw the screen's panel every frame (a person watches) until it ends; on the virtual clock without
        images the clock jumps to its end."""
        phase = screen.phase()
        clock = loop.clock
        start = clock.now_s()
        loop.gaze.set_plan(FixationPlan("cross", start, 1.0))
        for sink in loop.events:  # outside recorders (LSL markers) see each screen's onset
            sink.emit(SessionEvent("phase", -1, "session_screen", start, phase.name))
        paced_end = None if self.pacing == "live" and not screen.timed else start + screen.expected_s
        by = "timed" if screen.timed else self.pacing
        if paced_end is not None and not loop.config.every_frame:
            clock.sleep_until(paced_end)
            return start, clock.now_s(), by
        if paced_end is None and screen.questionnaire is not None and self.scale_input is not None:
            return self._pick_item(loop, screen, self.scale_input, start)
        t = start
        while True:
            if paced_end is not None and t >= paced_end - 1e-9:
                clock.sleep_until(paced_end)
                return start, clock.now_s(), by
            if paced_end is None:
                given = self._given(screen, row, start, clock.now_s())
                if given is not None:
                    return start, clock.now_s(), f"input:{given}"
            if not loop.config.every_frame:
                t += 0.01
                clock.sleep_until(t)
                continue
            t = _screen_frame(loop, phase, start, t)


    def _pick_item(self, loop: ScreenHost, screen: Screen, source: MappedRawSource, start: float
                   ) -> tuple[float, float, str]:
        """A questionnaire item answered with the controllers' stick (psyop.session.scale_picker): its screen drawn
        each frame with the highlighted point marked until a select button confirms it (no timeout)."""
        questionnaire = screen.questionnaire
        assert questionnaire is not None
        phase = screen.phase()

        def draw(request: FrameRequest, point: int) -> None:
            marked = dataclasses.replace(phase, text=questionnaire_text(questionnaire, screen.page, point - 1))
            _draw_screen(loop, marked, start, request)

        pacing = PickerPacing(loop.clock, loop.display, None, loop.config.every_frame, loop.frame_period_s)
        picker = run_picker(ScalePicker(len(scale_labels(questionnaire)), start), source, pacing, draw)
        return start, loop.clock.now_s(), f"controllers:{picker.point - 1}"


def scale_point(name: str, points: int) -> int | None:
    """The scale point a raw input names: a digit key (``3``, keypad ``kp_3``) or box button 0 .. points - 1."""
    digit = name.removeprefix("kp_")
    return int(digit) if len(digit) == 1 and digit.isdigit() and int(digit) < points else None


def _screen_frame(loop: ScreenHost, phase: ScreenPhase, start: float, t: float) -> float:
    """One frame of the screen at display slot ``t``; the next slot."""
    request = loop.display.begin_frame(t)
    _draw_screen(loop, phase, start, request)
    return max(t + loop.frame_period_s, request.display_time_s + request.period_s)


def _draw_screen(loop: ScreenHost, phase: ScreenPhase, start: float, request: FrameRequest) -> None:
    """Draw ``phase`` (shown since ``start``) into the display's frame ``request`` and hand it to the display."""
    loop.gaze.latest(loop.clock.now_s())
    check = None
    if loop.renderer is not None and request.should_render:
        check = loop.renderer.render(SCREEN_ROW, phase, "conventional", request.display_time_s - start,
                                     (0.0, 0.0, -1.0), frame=request)
    loop.display.end_frame(request, loop.renderer.eye_textures() if loop.renderer is not None else [])
    if check is not None and check.checked and not check.ok:
        raise RuntimeError(f"session screen {phase.name}: rendered frame failed its check")


def event_row(run: int, screen: Screen, moment: Moment, start: float, end: float, ended_by: str) -> JsonMapping:
    """The events log's row of one screen (psyop.session.log.screens_log.EVENTS_SCHEMA)."""
    return {"run": run, "screen": screen.screen, "name": screen.name, "page": screen.page,
            "n_pages": screen.n_pages, "when": moment.when, "before_trial": moment.before_trial,
            "block": moment.block, "after_trial": moment.after_trial, "trials_done": moment.done, "trials_left": moment.left, "start_s": start,
            "end_s": end, "duration_s": end - start if math.isfinite(end - start) else None,
            "ended_by": ended_by, "text": screen.text}


def session_screens(section: ScreensSection | None, *, pacing: Pacing, seed: int, recorder: ScreenRecorder | None,
                    fresh: bool, live_input: ScreenInput | None = None, raw_input: RawInput | None = None,
                    scale_input: MappedRawSource | None = None) -> ScreenRunner | None:
    """The screens of a run (None: the protocol has no ``session:``, and the loop runs as without it)."""
    if section is None:
        return None
    return ScreenRunner(section, pacing, int(seed), recorder, fresh, live_input, raw_input, scale_input)
