"""``n_afc``: which of n intervals, or of n locations, held the target (n-alternative forced choice, n = 2..8).

- ``alternatives: intervals``: the target interval (column ``correct_interval``, 1..n) shows the ``target``
  stimulus, every other interval the ``reference``; the answer is the interval's number.
- ``alternatives: locations``: one interval (``target`` sets its mode and factor overrides); the target location
  (column ``correct_location``, 1..n, in the order of ``locations_deg``) is written to the schedule as the scene
  variables ``target_azimuth_deg`` and ``target_elevation_deg``, which the target item reads as its
  ``centre_deg: [{factor: target_azimuth_deg}, {factor: target_elevation_deg}]``; the other locations are empty.
  The answer is the location's number.

Answers: keys 1..n (top row or keypad), response-box buttons 1..n; the OpenXR controllers answer n = 2 with their
select buttons (left: 1, right: 2) and n > 2 with a stick that moves the highlighted alternative (the response panel
names it, "interval 3 of 4" or "location 3 of 4", and a frame marks a highlighted location) and a select button that
confirms it (psyop.session.scale_picker, psyop.session.rating_stick); the alternatives highlighted go to
``choice_path`` (JSON ``[[t_s, alternative], ...]``; '' for other sources).
The analysis fits a psychometric function with guess rate 1/n per participant
and condition (psyop.statistics.psychometric, psignifit's nAFC type); the threshold is the level where the
proportion correct is halfway between 1/n and 1.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import ClassVar, Literal

import numpy as np
from pydantic import Field, model_validator

from psyop.protocol.base import Number
from psyop.protocol.scene import FactorRef
from psyop.protocol.kinds.base import (AnalysisTarget, Checks, Counterbalance, Inputs, InputSource, IntervalSpec,
                                       KindResponse, ObserverBase, ResponseKindSpec, ScheduleInput, Scored, StudyInputs,
                                       figure_target)
from psyop.protocol.kinds.confidence import SCALE_CONTROLLER, STICK_HELP
from psyop.protocol.kinds.modes import check_specs, interval_spec_columns, specs_factors
from psyop.protocol.image_observer import ImageObserver, unread_fields
from psyop.records import Loc, TrialRow

#: the alternatives n-AFC supports (psyop.statistics.psychometric fits guess 1/n for these)
N_CHOICES = range(2, 9)
#: locations: the scene variables (and schedule columns) holding the target's centre in each trial
LOCATION_AZIMUTH, LOCATION_ELEVATION = "target_azimuth_deg", "target_elevation_deg"
#: the trial-log column of the alternatives the controllers' stick highlighted before the answer (n > 2; '' for
#: other sources): JSON ``[[t_s, alternative], ...]``, as a rating's ``rating_path``
CHOICE_PATH = "choice_path"


def correct_alternative(row: TrialRow) -> int:
    """The trial's right answer, 1..n: its target location (locations) or its target interval (intervals)."""
    return int(row["correct_location"]) if "correct_location" in row else int(row["correct_interval"])


class NAfcResponse(KindResponse):
    """n-alternative forced choice over ``n`` intervals (one shows ``target``, the others ``reference``) or ``n``
    locations (``locations_deg``, the target item placed at one per trial)."""

    kind: Literal["n_afc"]
    #: the default: "Which interval showed the target?" (intervals), "Where was the target?" (locations)
    question: str = ""
    n: int = Field(ge=2, le=8, description="number of alternatives (2..8)")
    alternatives: Literal["intervals", "locations"] = "intervals"
    target: IntervalSpec
    reference: IntervalSpec | None = None
    #: locations: the n places of the target, each Fick [azimuth, elevation] in degrees (docs/optics.md, "Angles")
    locations_deg: list[tuple[Number, Number]] | None = None
    level_factor: str | None = None
    #: which interval holds the target: each equally often within a condition (balanced), or uniformly at random
    order: Counterbalance = "balanced"

    @model_validator(mode="before")
    @classmethod
    def _default_question(cls, data: object) -> object:
        if isinstance(data, dict) and "question" not in data:
            where = data.get("alternatives") == "locations"
            return {**data, "question": "Where was the target?" if where else "Which interval showed the target?"}
        return data

    def intervals(self) -> int:
        return self.n if self.alternatives == "intervals" else 1

    def level(self) -> str | None:
        return self.level_factor

    def interval_specs(self) -> tuple[IntervalSpec, ...]:
        return (self.target,) if self.reference is None else (self.target, self.reference)

    def scene_variables(self) -> dict[str, tuple[float, float]]:
        """locations: the target's centre per trial, each over its range of the locations."""
        if self.alternatives != "locations" or not self.locations_deg:
            return {}
        az, el = ([float(place[k]) for place in self.locations_deg] for k in (0, 1))
        return {LOCATION_AZIMUTH: (min(az), max(az)), LOCATION_ELEVATION: (min(el), max(el))}

    def factors_read(self) -> set[str]:
        return specs_factors(self.interval_specs(), self.level_factor)

    def picks_with_stick(self) -> bool:
        """Whether the controllers answer with the stick (n > 2: two select buttons cannot pick one of n)."""
        return self.n > 2

    def alternative_text(self, k: int) -> str:
        """How the response panel names alternative ``k`` (1..n) while the stick highlights it.

        Examples
        --------
        >>> NAfcResponse(kind="n_afc", n=4, target={"mode": "ocular"}, reference={"mode": "conventional"}
        ...              ).alternative_text(3)
        'interval 3 of 4'
        """
        noun = "interval" if self.alternatives == "intervals" else "location"
        return f"{noun} {int(k)} of {self.n}"


def _phi(z: float) -> float:
    return 0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))


class PsychometricNafc(ObserverBase):
    """p(correct) = 1/n + (1 - 1/n - lapse) * Phi((x - t) / width), x the trial's level (``level_column``) and
    t = ``threshold`` shifted per participant by N(0, ``between_subject_sd``); a wrong answer is one of the other
    n - 1 intervals, each equally likely."""

    kind: Literal["psychometric_nafc"]
    declared: ClassVar[bool] = True
    level_column: str
    threshold: Number
    width: Number = Field(gt=0)
    lapse: Number = Field(default=0.0, ge=0, lt=0.5)
    between_subject_sd: Number = Field(default=0.0, ge=0)

    def participant_draws(self, rng: np.random.Generator) -> dict[str, float]:
        sd = float(self.between_subject_sd)
        return {"threshold": float(self.threshold) + (float(rng.normal(0.0, sd)) if sd > 0 else 0.0)}

    def probability(self, row: TrialRow, participant: Mapping[str, float]) -> float:
        """p(correct) in trial ``row`` (``n_alternatives`` is the trial's n)."""
        guess = 1.0 / int(row["n_alternatives"])
        x = float(row[self.level_column])
        return guess + (1.0 - guess - float(self.lapse)) * _phi((x - participant["threshold"]) / float(self.width))

    def answer(self, row: TrialRow, participant: Mapping[str, float], u: float) -> str:
        p, right, n = self.probability(row, participant), correct_alternative(row), int(row["n_alternatives"])
        if u < p:
            return str(right)
        others = [k for k in range(1, n + 1) if k != right]
        return str(others[min(int((u - p) / (1.0 - p) * (n - 1)), n - 2)])


def balanced_alternatives(condition: np.ndarray, practice: np.ndarray, n: int, rng: np.random.Generator
                          ) -> np.ndarray:
    """1..n per trial: within each condition's main trials each alternative floor(R / n) times and the remainder
    on distinct alternatives drawn at random, in a random order; practice trials uniformly at random."""
    out = np.empty(condition.size, dtype=np.int64)
    out[practice] = rng.integers(1, n + 1, size=int(practice.sum()))
    for value in np.unique(condition[~practice]):
        where = np.flatnonzero((condition == value) & ~practice)
        reps = where.size
        cells = np.concatenate([np.repeat(np.arange(1, n + 1), reps // n),
                                rng.choice(np.arange(1, n + 1), size=reps % n, replace=False)])
        out[where] = rng.permutation(cells)
    return out


def _reads_location(item: object) -> bool:
    """Whether a scene item's ``centre_deg`` reads the target's location (``{factor: target_azimuth_deg}`` or
    ``{factor: target_elevation_deg}``)."""
    centre = getattr(item, "centre_deg", None)
    parts = centre if isinstance(centre, tuple) else ()
    return any(isinstance(part, FactorRef) and part.factor in (LOCATION_AZIMUTH, LOCATION_ELEVATION) for part in parts)


def check_locations(response: NAfcResponse, checks: Checks, path: Loc) -> None:
    """alternatives: locations: n distinct places inside the display's field of view, a scene item that reads
    them, and no reference (the other places are empty)."""
    from psyop.protocol.display import resolve_display_profile

    places = response.locations_deg
    if places is None or len(places) != response.n:
        checks.add(path + (("locations_deg",) if places is not None else ("alternatives",)),
                   f"alternatives: locations needs locations_deg with n = {response.n} places, each [azimuth_deg, "
                   f"elevation_deg] (got {0 if places is None else len(places)})")
        return
    if len({(float(a), float(e)) for a, e in places}) != len(places):
        checks.add(path + ("locations_deg",), "two locations are the same place; give n distinct places")
    display = resolve_display_profile(checks.p.display)
    half_w, half_h = display.horizontal_fov_deg / 2, display.vertical_fov_deg / 2
    for k, (az, el) in enumerate(places):
        if abs(float(az)) >= half_w or abs(float(el)) >= half_h:
            checks.add(path + ("locations_deg", k), f"location {k + 1} at [{float(az):g}, {float(el):g}] deg is "
                                                    f"outside the display's field of view (+-{half_w:g} deg across, "
                                                    f"+-{half_h:g} deg up and down); move it inside")
    if response.reference is not None:
        checks.add(path + ("reference",), "with alternatives: locations the other locations are empty, so a reference "
                                          "is not shown; remove it")
    if not any(_reads_location(item) for item in checks.p.scene):
        checks.add(path + ("alternatives",), f"nothing in the scene is placed at the drawn location: give the target "
                                             f"item centre_deg: [{{factor: {LOCATION_AZIMUTH}}}, "
                                             f"{{factor: {LOCATION_ELEVATION}}}]")


class NAfc(ResponseKindSpec):
    name = "n_afc"
    label = "n-AFC"
    takes_confidence = True  # one discrete choice: a confidence rating may follow
    model = NAfcResponse
    observer_models = (PsychometricNafc, ImageObserver)
    fields = {"NAfcResponse": {"kind": "plan", "question": "plan", "n": "kinds", "alternatives": "kinds",
                               "target": "kinds", "reference": "kinds", "locations_deg": "kinds",
                               "level_factor": "kinds", "order": "kinds"},
              "PsychometricNafc": {k: "kinds" for k in ("kind", "level_column", "threshold", "width", "lapse",
                                                        "between_subject_sd")},
              "ImageObserver": {k: "image_observer" for k in ImageObserver.model_fields if k != "eye"}}

    def inputs(self, response: KindResponse) -> Inputs:
        """Keys 1..n (and the keypad's); box buttons 1..n; the controllers' two select buttons for n = 2, their
        stick and select buttons (the scale's map, :data:`SCALE_CONTROLLER`) for n > 2."""
        assert isinstance(response, NAfcResponse)
        numbers = [str(k) for k in range(1, response.n + 1)]
        keys = {k: k for k in numbers} | {f"kp_{k}": k for k in numbers} | \
            ({"left": "1", "right": "2"} if response.n == 2 else {})
        controller = dict(SCALE_CONTROLLER) if response.picks_with_stick() else {"left": "1", "right": "2"}
        return Inputs(keys, {k: k for k in numbers}, controller)

    def answer_keys_text(self, response: KindResponse, source: InputSource) -> str | None:
        """For the controllers with n > 2, how to move among the alternatives and answer (:data:`STICK_HELP`); else
        each answer's inputs."""
        assert isinstance(response, NAfcResponse)
        if source == "openxr" and response.picks_with_stick():
            return STICK_HELP
        return super().answer_keys_text(response, source)

    def columns(self, response: KindResponse, schedule: ScheduleInput) -> dict[str, np.ndarray]:
        """``n_alternatives``; n > 2: the empty ``choice_path``; intervals: ``correct_interval`` (1..n), each
        interval's mode and the factors an interval sets; locations: ``correct_location`` (1..n), the target's centre
        (``target_azimuth_deg``, ``target_elevation_deg``) and the one interval's mode and factors."""
        assert isinstance(response, NAfcResponse)
        n, columns, rows = response.n, schedule.columns, schedule.n
        if response.order == "balanced":
            right = balanced_alternatives(schedule.condition, schedule.practice.astype(bool), n, schedule.rng)
        else:
            right = schedule.rng.integers(1, n + 1, size=rows)
        out: dict[str, np.ndarray] = {"n_alternatives": np.full(rows, n, dtype=np.int64)}
        if response.picks_with_stick():
            out[CHOICE_PATH] = np.full(rows, "", dtype=object)
        if response.alternatives == "locations":
            places = np.asarray(response.locations_deg, dtype=np.float64)
            out |= {"correct_location": right, LOCATION_AZIMUTH: places[right - 1, 0],
                    LOCATION_ELEVATION: places[right - 1, 1]}
            out.update(interval_spec_columns(1, response.target, response.target, np.ones(rows, bool), columns))
            return out
        assert response.reference is not None  # check(): intervals need one
        out["correct_interval"] = right
        for k in range(1, n + 1):
            out.update(interval_spec_columns(k, response.target, response.reference, right == k, columns))
        return out

    def check(self, response: KindResponse, checks: Checks, path: Loc) -> None:
        """Numeric level and set factors; mode factors name modes. Intervals: a reference that differs from the
        target, no locations. Locations: n distinct places inside the display, read by a scene item, no reference."""
        assert isinstance(response, NAfcResponse)
        specs = {"target": response.target} | ({} if response.reference is None else {"reference": response.reference})
        check_specs(checks, path, specs, response.level_factor)
        if response.alternatives == "locations":
            check_locations(response, checks, path)
            return
        if response.locations_deg is not None:
            checks.add(path + ("locations_deg",), "locations_deg places the target in alternatives: locations; remove "
                                                  "it, or set alternatives: locations")
        if response.reference is None:
            checks.add(path, "alternatives: intervals needs a reference: the stimulus of the other n - 1 intervals "
                             "(e.g. reference: {mode: conventional})")
        elif response.target == response.reference:
            checks.add(path + ("reference",), "target and reference are the same stimulus, so no interval could be "
                                              "told apart; give the reference another mode or a set: "
                                              "(e.g. set: {level_D: 0})")

    def check_observer(self, observer: ObserverBase, response: KindResponse, checks: Checks, path: Loc) -> None:
        if isinstance(observer, ImageObserver):  # answers from the frames of each interval
            assert isinstance(response, NAfcResponse)
            if response.alternatives != "intervals":
                checks.add(path + ("kind",), "the image observer answers n_afc over intervals only (the interval with "
                                             "the most relative motion); use kind: psychometric_nafc for locations")
            for name in unread_fields(observer, self.name):
                checks.add(path + (name,), f"the image observer's n-AFC rule does not read {name}; remove it")
            return
        assert isinstance(observer, PsychometricNafc) and isinstance(response, NAfcResponse)
        if checks.factor_exists(observer.level_column, path + ("level_column",), numeric=True) and \
                observer.level_column != response.level_factor:
            checks.add(path + ("level_column",), f"the observer reads '{observer.level_column}' as its level, but the "
                                                 f"response's level_factor is {response.level_factor!r}; set "
                                                 f"response.level_factor: {observer.level_column}")

    def score(self, row: TrialRow, answer: str) -> Scored:
        return Scored(correct=answer == str(correct_alternative(row)))

    def targets(self, study: StudyInputs) -> list[AnalysisTarget]:
        """Fits with guess 1/n per participant and condition in results/, and their figure."""
        return [figure_target(study, "n_afc", "analysis/n_afc.py")]


KIND = NAfc()
