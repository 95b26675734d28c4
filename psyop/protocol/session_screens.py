"""The optional ``session:`` section: what a participant sees around the trials.

Instructions before the first trial (and again at the start of chosen blocks), rest breaks (every N trials
and/or between blocks), questionnaires (at the start, between blocks, at the end; ``name: ssq`` is the
Simulator Sickness Questionnaire, psyop.protocol.ssq) and an end screen. Each screen is a head-fixed text
panel the session loop shows (psyop.session.screens), ended by the participant (a simulated one after the
screen's ``expected_s``); docs/session_screens.md.
"""

from __future__ import annotations

import string
import textwrap
from typing import Any, Literal

from pydantic import Field, field_validator, model_validator

from psyop.protocol import ssq
from psyop.protocol.base import Integer, Number, StrictModel

#: a screen's text is wrapped at this many characters per line (psyop.rendering.text.WRAP_CHARS, which draws it),
#: or fewer where the display's view is too narrow for them at the legible minimum (psyop.session.text_fit)
WRAP_CHARS = 40
#: the most lines a screen's text may take once wrapped at WRAP_CHARS, on any display; a display with too few pixels
#: for it at the legible minimum (capitals of 12 px) refuses it when the session starts (psyop.session.text_fit)
MAX_LINES = 16
#: the placeholders a break's text may hold
BREAK_FIELDS: tuple[str, ...] = ("done", "left", "total")
DEFAULT_BREAK_TEXT = "{done} trials done, {left} left.\nTake a rest; press a key when ready."

When = Literal["start", "between_blocks", "end"]


def screen_lines(text: str) -> int:
    """How many lines ``text`` takes on its panel (each of its own lines wrapped at :data:`WRAP_CHARS`)."""
    return sum(len(textwrap.wrap(line, WRAP_CHARS)) or 1 for line in text.strip("\n").split("\n"))


def _fits(text: str) -> str:
    if not text.strip():
        raise ValueError("the text is empty; write what the participant reads")
    n = screen_lines(text)
    if n > MAX_LINES:
        raise ValueError(f"the text takes {n} lines on the panel ({WRAP_CHARS} characters a line), more than "
                         f"{MAX_LINES} fit in view; shorten it or split it into pages")
    return text


class InstructionPage(StrictModel):
    """One page of instructions: ``text`` (its own line breaks kept), optionally an ``image`` drawn above it on the
    panel, ``image_width_deg`` wide (None: as wide as the view leaves room for); the participant ends it. The image
    file (relative to the protocol) is decoded at validation (psyop.protocol.semantics) and the page laid out on
    the display when the session starts (psyop.rendering.text: refused at its line when it cannot fit)."""

    text: str = Field(max_length=2000, description="what the participant reads (line breaks kept)")
    image: str | None = Field(default=None, description="an image file (PNG, JPEG; relative to the protocol) drawn "
                                                        "above the text")
    image_width_deg: Number | None = Field(default=None, gt=0, le=120,
                                           description="the image's width, deg (default: as wide as fits the view)")
    expected_s: Number = Field(default=15.0, gt=0, le=600,
                               description="how long a simulated participant reads it, s")

    @field_validator("text")
    @classmethod
    def _text(cls, value: str) -> str:
        return _fits(value)

    @field_validator("image")
    @classmethod
    def _image(cls, value: str | None) -> str | None:
        if value is not None and not value.strip():
            raise ValueError("image is empty; name an image file (relative to the protocol) or remove image:")
        return value

    @model_validator(mode="after")
    def _width_needs_image(self) -> "InstructionPage":
        if self.image_width_deg is not None and self.image is None:
            raise ValueError("image_width_deg is given but the page has no image; add image: FILE or remove "
                             "image_width_deg")
        return self


class Instructions(StrictModel):
    """``instructions:``: pages shown before the session's first trial, and again at the start of each block in
    ``at_blocks`` (block numbers in run order, 0 the first main block; psyop.schedule)."""

    pages: list[InstructionPage] = Field(min_length=1, max_length=50)
    at_blocks: list[Integer] = Field(default_factory=list, max_length=1000,
                                     description="blocks (run order, from 0) before which the pages are shown again")

    @field_validator("at_blocks")
    @classmethod
    def _blocks(cls, value: list[int]) -> list[int]:
        if any(b < 0 for b in value):
            raise ValueError("block numbers start at 0 (the first main block); the instructions already come "
                             "before the first trial")
        if len(set(value)) != len(value):
            raise ValueError("a block is listed twice; list each once")
        return value


class Breaks(StrictModel):
    """``breaks:``: a rest screen after every ``every_trials`` recorded trials and/or between blocks, ended by
    the participant; ``text`` may say ``{done}``, ``{left}`` and ``{total}`` trials."""

    every_trials: Integer | None = Field(default=None, description="a break after every N recorded trials")
    between_blocks: bool = Field(default=False, description="a break when the block changes")
    text: str = Field(default=DEFAULT_BREAK_TEXT, max_length=2000)
    expected_s: Number = Field(default=30.0, gt=0, le=3600, description="how long a simulated participant rests, s")

    @field_validator("every_trials")
    @classmethod
    def _every(cls, value: int | None) -> int | None:
        if value is not None and value < 1:
            raise ValueError(f"every_trials must be 1 or more (a break after every N recorded trials), got {value}; "
                             "write a positive number, or leave every_trials out for no periodic break")
        return value

    @field_validator("text")
    @classmethod
    def _text(cls, value: str) -> str:
        try:
            names = {f for _, f, _, _ in string.Formatter().parse(value) if f is not None}
            unknown = sorted(names - set(BREAK_FIELDS))
            if unknown:
                raise ValueError(f"unknown placeholder(s) {unknown}; use {{done}}, {{left}} or {{total}}")
            sample = value.format(done=100, left=100, total=200)
        except (IndexError, KeyError) as error:
            raise ValueError(f"the text is not a valid template ({error}); write placeholders as {{done}}, "
                             "{left} or {total}, and a literal brace as {{ or }}") from None
        except ValueError as error:
            if "placeholder" in str(error):
                raise
            raise ValueError(f"the text is not a valid template ({error}); write placeholders as {{done}}, "
                             "{left} or {total}, and a literal brace as {{ or }}") from None
        _fits(sample)
        return value

    @model_validator(mode="after")
    def _some(self) -> "Breaks":
        if self.every_trials is None and not self.between_blocks:
            raise ValueError("breaks: needs every_trials: N and/or between_blocks: true")
        return self


class Scale(StrictModel):
    """A rating scale: answers 0 .. points - 1, each with its label."""

    points: Integer = Field(description="how many answers (0 .. points - 1)")
    labels: list[str] = Field(description="one label per point, lowest first")

    @field_validator("points")
    @classmethod
    def _points(cls, value: int) -> int:
        if not 2 <= value <= 11:
            raise ValueError(f"a scale needs 2 to 11 points, got {value}; change points:")
        return value

    @model_validator(mode="after")
    def _labels(self) -> "Scale":
        if len(self.labels) != self.points:
            raise ValueError(f"the scale has {self.points} points but {len(self.labels)} labels; give one label per "
                             "point (lowest first), or change points:")
        if any(not label.strip() or len(label) > 40 for label in self.labels):
            raise ValueError("each label must be 1 to 40 characters")
        return self


class Questionnaire(StrictModel):
    """A questionnaire: its items rated on its scale, one item per screen, at the moments ``when`` names.
    ``name: ssq`` alone is the Simulator Sickness Questionnaire (psyop.protocol.ssq: its 16 items, 0-3 scale)."""

    name: str = Field(pattern=r"^[a-z][a-z0-9_]*$", max_length=32, description="lower_snake_case; 'ssq': the SSQ")
    when: list[When] = Field(min_length=1, description="start, between_blocks and/or end")
    items: list[str] | None = Field(default=None, max_length=100, description="the statements rated (not for ssq)")
    scale: Scale | None = Field(default=None, description="the rating scale (not for ssq: 0-3)")
    title: str | None = Field(default=None, max_length=80, description="shown above each item (default: the name)")
    item_expected_s: Number = Field(default=4.0, gt=0, le=600,
                                    description="how long a simulated participant takes per item, s")

    @field_validator("when", mode="before")
    @classmethod
    def _one_or_more(cls, value: Any) -> Any:  # Any: pydantic validator input
        return [value] if isinstance(value, str) else value

    @field_validator("when")
    @classmethod
    def _once_each(cls, value: list[str]) -> list[str]:
        if len(set(value)) != len(value):
            raise ValueError("name each of start, between_blocks, end at most once")
        return value

    @field_validator("items")
    @classmethod
    def _items(cls, value: list[str] | None) -> list[str] | None:
        for item in value or []:
            _fits(item)
        return value

    @model_validator(mode="after")
    def _complete(self) -> "Questionnaire":
        if self.name == ssq.NAME:
            if self.items is not None or self.scale is not None:
                raise ValueError("name: ssq is the published Simulator Sickness Questionnaire: its 16 items and 0-3 "
                                 "scale are fixed; remove items:/scale:, or give your questionnaire another name")
            return self
        if not self.items:
            raise ValueError(f"questionnaire '{self.name}' has no items; list the statements under items: [...] "
                             "(only name: ssq brings its own)")
        if self.scale is None:
            raise ValueError(f"questionnaire '{self.name}' has no scale; add scale: {{points: N, labels: [...]}}")
        return self


class EndScreen(StrictModel):
    """``end_screen:``: shown once the last trial (and the end questionnaires) are done."""

    text: str = Field(max_length=2000)
    expected_s: Number = Field(default=5.0, gt=0, le=600, description="how long a simulated participant reads it, s")

    @field_validator("text")
    @classmethod
    def _text(cls, value: str) -> str:
        return _fits(value)


#: the placeholder an answer's feedback text may hold (the answer given, as trials.parquet's ``response``)
FEEDBACK_FIELDS: tuple[str, ...] = ("answer",)


class FeedbackText(StrictModel):
    """What the feedback screen says: ``correct`` / ``incorrect`` after a trial the response kind scores,
    ``answer`` (may say ``{answer}``) after one whose kind has no correct answer (e.g. a rating), ``timeout``
    after a trial nobody answered in time."""

    correct: str = Field(default="Correct", max_length=200)
    incorrect: str = Field(default="Incorrect", max_length=200)
    answer: str = Field(default="Your answer: {answer}", max_length=200)
    timeout: str = Field(default="No answer in time", max_length=200)

    @field_validator("correct", "incorrect", "timeout")
    @classmethod
    def _plain(cls, value: str) -> str:
        return _fits(value)

    @field_validator("answer")
    @classmethod
    def _answer(cls, value: str) -> str:
        try:
            names = {f for _, f, _, _ in string.Formatter().parse(value) if f is not None}
            unknown = sorted(names - set(FEEDBACK_FIELDS))
            sample = "" if unknown else value.format(answer="0.000000")
        except (IndexError, KeyError, ValueError) as error:
            raise ValueError(f"the text is not a valid template ({error}); write the placeholder as {{answer}} and "
                             "a literal brace as {{ or }}") from None
        if unknown:
            raise ValueError(f"unknown placeholder(s) {unknown}; use {{answer}}")
        _fits(sample)
        return value


class Feedback(StrictModel):
    """``feedback:``: a short head-fixed screen after each recorded trial of the kinds chosen (``practice``
    trials, ``main`` trials), shown for ``duration_s`` (not ended by the participant), saying whether the
    answer was correct (or, for a kind with no correct answer, what it was)."""

    practice: bool = Field(default=True, description="after each practice trial")
    main: bool = Field(default=False, description="after each main (analysed) trial")
    text: FeedbackText = Field(default_factory=FeedbackText)
    duration_s: Number = Field(default=1.0, gt=0, le=60, description="how long the feedback shows, s")


class SimulatedAnswers(StrictModel):
    """How a simulated participant answers questionnaires: a severity in [0, 1] drawn once per participant
    (normal, ``severity_mean``, ``severity_sd``, clipped), each answer the severity's point on the scale plus
    normal noise of ``item_sd`` points, rounded and clipped (psyop.session.screens)."""

    severity_mean: Number = Field(default=0.15, ge=0, le=1)
    severity_sd: Number = Field(default=0.1, ge=0, le=1)
    item_sd: Number = Field(default=0.5, ge=0, le=5, description="per-answer noise, scale points")


class SessionScreens(StrictModel):
    """``session:``: instructions, breaks, questionnaires, feedback after trials and the end screen (all
    optional)."""

    instructions: Instructions | None = None
    breaks: Breaks | None = None
    questionnaires: list[Questionnaire] = Field(default_factory=list, max_length=20)
    end_screen: EndScreen | None = None
    feedback: Feedback | None = None
    simulated_answers: SimulatedAnswers = Field(default_factory=SimulatedAnswers)

    @field_validator("questionnaires")
    @classmethod
    def _unique(cls, value: list[Questionnaire]) -> list[Questionnaire]:
        names = [q.name for q in value]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"questionnaire {twice[0]!r} is listed twice; list it once with all its times in when:")
        return value
