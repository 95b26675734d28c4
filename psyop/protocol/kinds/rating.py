"""``rating``: how much of a quality the stimulus had, on a k-point scale (2 to 9 points, keys 1..k). Each trial
shows the ``stimulus`` once (its mode fixed or a mode factor's level, with factor overrides); the answer is the
point's number, which the trial table also holds as ``response_value``. The keyboard answers with the digits 1..k, a
response box with its buttons 1..k; the OpenXR controllers move a highlighted point along the scale with a stick and
confirm it with a select button (psyop.session.scale_picker), and the points highlighted go to ``rating_path``
(JSON ``[[t_s, point], ...]``). No answer is correct. The analysis
(analysis/rating.py) reports the mean rating per condition with t intervals, the repeated-measures ANOVA of the
participants' means and a cumulative-link (ordinal probit) model (psyop.statistics.ratings).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from statistics import NormalDist
from typing import Any, ClassVar, Literal

import numpy as np
from pydantic import Field, field_validator

from psyop.protocol.base import Integer, Number, StrictModel, format_level
from psyop.protocol.kinds.base import (AnalysisTarget, Checks, Inputs, InputSource, IntervalSpec, KindResponse,
                                       ObserverBase, ResponseKindSpec, ScheduleInput, Scored, StudyInputs,
                                       figure_target)
from psyop.protocol.kinds.confidence import SCALE_CONTROLLER, STICK_HELP, scale_lines
from psyop.protocol.kinds.modes import check_specs, interval_spec_columns, specs_factors
from psyop.records import Loc, TrialRow

#: the fewest and most points a scale may have (its keys are the digits 1..k)
MIN_POINTS, MAX_POINTS = 2, 9
#: the schedule column holding the scale's number of points (what the simulated observer and the analysis read)
POINTS_COLUMN = "scale_points"
#: the trial-log column of the points the controllers highlighted before the answer ('' for other sources)
PATH_COLUMN = "rating_path"


class RatingScale(StrictModel):
    """The scale: ``points`` (k, 2 to 9; answered 1..k) and optionally one label per point, lowest first."""

    points: Integer
    labels: list[str] | None = None


class RatingResponse(KindResponse):
    """A rating of one interval showing ``stimulus`` on ``scale``."""

    kind: Literal["rating"]
    intervals_needed: ClassVar[int] = 1
    question: str = "How would you rate what you saw?"
    stimulus: IntervalSpec
    scale: RatingScale

    def interval_specs(self) -> tuple[IntervalSpec, ...]:
        return (self.stimulus,)

    def factors_read(self) -> set[str]:
        return specs_factors((self.stimulus,))


def _level_key(value: object) -> str:
    """A factor level as the observer's ``means`` keys spell it (``ocular``, ``0.5``, ``1``)."""
    if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool):
        return format_level(float(value))
    return str(value)


class RatingObserver(ObserverBase):
    """A latent-normal rater: on each trial latent = mean + o + e, the mean from ``means`` (one number, or per level
    of ``factor``), o ~ N(0, ``between_subject_sd``) drawn once per participant, e ~ N(0, ``sd``) per trial; the
    rating is the point whose [j - 0.5, j + 0.5) holds the latent (cut points 1.5, ..., k - 0.5; the ends open),
    so ``means`` are on the rating scale."""

    kind: Literal["rating"]
    declared: ClassVar[bool] = True
    #: the factor whose level picks the mean (None: ``means`` is one number for every trial)
    factor: str | None = None
    means: dict[str, Number] | Number
    sd: Number = Field(default=1.0, gt=0)
    between_subject_sd: Number = Field(default=0.0, ge=0)

    @field_validator("means", mode="before")
    @classmethod
    def _numeric_level_keys(cls, value: Any) -> Any:  # Any: pydantic validator input
        """Numeric level keys (YAML ``0.5: 3``) are spelled as the factor's levels are (``format_level``)."""
        if isinstance(value, dict):
            return {_level_key(k): v for k, v in value.items()}
        return value

    def mean(self, row: TrialRow) -> float:
        """The population mean of the latent in trial ``row``."""
        if not isinstance(self.means, dict):
            return float(self.means)
        assert self.factor is not None
        return float(self.means[_level_key(row.get(f"{self.factor}_interval1", row[self.factor]))])

    def participant_draws(self, rng: np.random.Generator) -> dict[str, float]:
        sd = float(self.between_subject_sd)
        return {"offset": float(rng.normal(0.0, sd)) if sd > 0 else 0.0}

    def latent(self, row: TrialRow, participant: Mapping[str, float], u: float) -> float:
        """The trial's latent value from its uniform ``u`` in [0, 1) (u = 0 read as the smallest draw above 0)."""
        z = NormalDist().inv_cdf(min(max(u, 2.0 ** -53), 1.0 - 2.0 ** -53))
        return self.mean(row) + participant["offset"] + float(self.sd) * z

    def answer(self, row: TrialRow, participant: Mapping[str, float], u: float) -> str:
        points = int(row[POINTS_COLUMN])
        return str(min(max(math.floor(self.latent(row, participant, u) + 0.5), 1), points))


def _scale_keys(points: int) -> dict[str, str]:
    digits = {str(j): str(j) for j in range(1, points + 1)}
    return digits | {f"kp_{j}": str(j) for j in range(1, points + 1)}


class Rating(ResponseKindSpec):
    name = "rating"
    label = "rating scale"
    model = RatingResponse
    observer_models = (RatingObserver,)
    # the maps depend on the scale's points: inputs() gives them for a protocol (none without one)
    keys: ClassVar[Mapping[str, str]] = {}
    buttons: ClassVar[Mapping[str, str]] = {}
    #: a stick moves the highlighted point, a select button confirms it (psyop.session.scale_picker)
    controller: ClassVar[Mapping[str, str]] = SCALE_CONTROLLER
    fields = {"RatingResponse": {"kind": "plan", "question": "plan", "stimulus": "kinds", "scale": "kinds"},
              "RatingScale": {"points": "kinds", "labels": "kinds"},
              "RatingObserver": {k: "kinds" for k in ("kind", "factor", "means", "sd", "between_subject_sd")}}

    def inputs(self, response: KindResponse) -> Inputs:
        """Keys 1..k (and the keypad's), response-box buttons 1..k; the controllers' stick and select buttons."""
        assert isinstance(response, RatingResponse)
        points = max(0, min(int(response.scale.points), MAX_POINTS))
        return Inputs(keys=_scale_keys(points), buttons={str(j): str(j) for j in range(1, points + 1)},
                      controller=dict(SCALE_CONTROLLER))

    def columns(self, response: KindResponse, schedule: ScheduleInput) -> dict[str, np.ndarray]:
        """The interval's mode, the factors the stimulus sets, the scale's points and the empty path."""
        assert isinstance(response, RatingResponse)
        every = np.ones(schedule.n, dtype=bool)
        out = interval_spec_columns(1, response.stimulus, response.stimulus, every, schedule.columns)
        out[POINTS_COLUMN] = np.full(schedule.n, int(response.scale.points), dtype=np.int64)
        out[PATH_COLUMN] = np.full(schedule.n, "", dtype=object)
        return out

    def check(self, response: KindResponse, checks: Checks, path: Loc) -> None:
        """The scale has 2 to 9 points and, with labels, one label per point; every factor the stimulus sets is
        numeric; a mode factor names modes."""
        assert isinstance(response, RatingResponse)
        scale, points = response.scale, int(response.scale.points)
        if not MIN_POINTS <= points <= MAX_POINTS:
            checks.add(path + ("scale", "points"), f"a rating scale has {MIN_POINTS} to {MAX_POINTS} points (keys 1 to "
                                                   f"{MAX_POINTS}), not {points}")
        elif scale.labels is not None and len(scale.labels) != points:
            checks.add(path + ("scale", "labels"), f"{len(scale.labels)} label(s) for a {points}-point scale: give one "
                                                   f"label per point, lowest first, or leave labels out")
        check_specs(checks, path, {"stimulus": response.stimulus})

    def check_observer(self, observer: ObserverBase, response: KindResponse, checks: Checks, path: Loc) -> None:
        """``means`` is one number without a factor, else one mean per level of ``factor`` (none missing, none
        extra)."""
        assert isinstance(observer, RatingObserver) and isinstance(response, RatingResponse)
        means = observer.means
        if observer.factor is None:
            if isinstance(means, dict):
                checks.add(path + ("means",), "means are given per level, but the observer names no factor; add "
                                              "factor: NAME (the factor whose levels these are)")
            return
        if not isinstance(means, dict):
            checks.add(path + ("means",), f"means is one number, but the observer reads factor '{observer.factor}'; "
                                          f"give one mean per level (means: {{level: mean}}) or leave factor out")
            return
        if not checks.factor_exists(observer.factor, path + ("factor",)):
            return
        levels = [_level_key(level) for level in checks.factors[observer.factor].all_levels()]
        for level in levels:
            if level not in means:
                checks.add(path + ("means",), f"no mean for {observer.factor} level '{level}'; add '{level}: <mean "
                                              f"rating>' under means")
        for key in means:
            if key not in levels:
                checks.add(path + ("means", key), f"'{key}' is not a level of {observer.factor} "
                                                  f"({', '.join(levels)})")

    def score(self, row: TrialRow, answer: str) -> Scored:
        return Scored(correct=None)

    def response_text(self, response: KindResponse) -> str | None:
        """The scale under the prompt: each point's key and label, lowest first; without labels the keys' range."""
        assert isinstance(response, RatingResponse)
        return self.scale_text(response, None)

    @staticmethod
    def scale_text(response: RatingResponse, highlighted: int | None) -> str:
        """The scale's lines, with ``highlighted`` marked (the point a controller has moved to), or none."""
        return scale_lines(int(response.scale.points), response.scale.labels, ("lowest", "highest"), highlighted)

    def answer_keys_text(self, response: KindResponse, source: InputSource) -> str | None:
        """For the controllers, how to move along the scale and answer (:data:`STICK_HELP`); else None: the scale
        under the prompt (:meth:`response_text`) already names each point by its digit, the key and the
        response-box button that give it."""
        return STICK_HELP if source == "openxr" else None

    def targets(self, study: StudyInputs) -> list[AnalysisTarget]:
        """Mean ratings, the ANOVA and the ordinal model in results/ and their figure (analysis/rating.py)."""
        return [figure_target(study, "rating", "analysis/rating.py")]


KIND = Rating()
