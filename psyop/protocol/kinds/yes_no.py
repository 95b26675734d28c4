"""``yes_no``: was the signal there? Each trial shows the ``signal`` or the ``noise`` stimulus in one interval
(column ``signal``, balanced within each condition or a fair coin per trial); the answer is ``yes`` or ``no``.
The analysis reports hit and false-alarm rates, d' and criterion per condition (log-linear correction,
psyop.statistics.signal_detection) and, with a level factor, a psychometric fit of "yes" with a free guess rate.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import ClassVar, Literal

import numpy as np
from pydantic import Field

from psyop.protocol.base import Number
from psyop.protocol.kinds.base import (AnalysisTarget, Checks, Counterbalance, IntervalSpec, KindResponse, ObserverBase,
                                       ResponseKindSpec, ScheduleInput, Scored, StudyInputs)
from psyop.protocol.kinds.modes import check_specs, interval_spec_columns, specs_factors
from psyop.protocol.image_observer import ImageObserver, unread_fields
from psyop.records import Loc, TrialRow


class YesNoResponse(KindResponse):
    """Yes/no detection: one interval showing ``signal`` (column ``signal`` true) or ``noise``."""

    kind: Literal["yes_no"]
    intervals_needed: ClassVar[int] = 1
    question: str = "Was the signal there?"
    signal: IntervalSpec
    noise: IntervalSpec
    #: the factor whose level the signal has (a psychometric fit of "yes" over it); None: d' per condition only
    level_factor: str | None = None
    #: how signal and noise trials are assigned: half each per condition (balanced), or a fair coin per trial
    signal_trials: Counterbalance = "balanced"

    @property
    def counterbalance(self) -> Counterbalance:
        return self.signal_trials

    def level(self) -> str | None:
        return self.level_factor

    def interval_specs(self) -> tuple[IntervalSpec, ...]:
        return (self.signal, self.noise)

    def factors_read(self) -> set[str]:
        return specs_factors(self.interval_specs(), self.level_factor)


def _phi(z: float) -> float:
    return 0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))


class PsychometricYesNo(ObserverBase):
    """p("yes") on a signal trial = false_alarm_rate + (1 - false_alarm_rate - lapse) * Phi((x - t) / width),
    x the trial's level (``level_column``, as the signal interval shows it) and t = ``threshold`` shifted per
    participant by N(0, ``between_subject_sd``); on a noise trial p("yes") = ``false_alarm_rate``."""

    kind: Literal["psychometric_yes_no"]
    declared: ClassVar[bool] = True
    level_column: str
    threshold: Number
    width: Number = Field(gt=0)
    false_alarm_rate: Number = Field(ge=0, lt=1)
    lapse: Number = Field(default=0.0, ge=0, lt=0.5)
    between_subject_sd: Number = Field(default=0.0, ge=0)

    def participant_draws(self, rng: np.random.Generator) -> dict[str, float]:
        sd = float(self.between_subject_sd)
        return {"threshold": float(self.threshold) + (float(rng.normal(0.0, sd)) if sd > 0 else 0.0)}

    def probability(self, row: TrialRow, participant: Mapping[str, float]) -> float:
        """p("yes") in trial ``row``."""
        fa = float(self.false_alarm_rate)
        if not bool(row["signal"]):
            return fa
        level = row.get(f"{self.level_column}_interval1", row[self.level_column])
        return fa + (1.0 - fa - float(self.lapse)) * _phi((float(level) - participant["threshold"]) / float(self.width))

    def answer(self, row: TrialRow, participant: Mapping[str, float], u: float) -> str:
        return "yes" if u < self.probability(row, participant) else "no"


class YesNo(ResponseKindSpec):
    name = "yes_no"
    label = "yes/no"
    takes_confidence = True  # one discrete choice: a confidence rating may follow
    model = YesNoResponse
    observer_models = (PsychometricYesNo, ImageObserver)
    keys = {"y": "yes", "n": "no", "left": "yes", "right": "no"}
    buttons = {"1": "yes", "2": "no", "L": "yes", "R": "no", "Y": "yes", "N": "no"}
    controller = {"left": "yes", "right": "no"}
    fields = {"YesNoResponse": {"kind": "plan", "question": "plan", "signal": "kinds", "noise": "kinds",
                                "level_factor": "kinds", "signal_trials": "kinds"},
              "PsychometricYesNo": {k: "kinds" for k in ("kind", "level_column", "threshold", "width",
                                                         "false_alarm_rate", "lapse", "between_subject_sd")},
              "ImageObserver": {k: "image_observer" for k in ImageObserver.model_fields if k != "eye"}}

    def columns(self, response: KindResponse, schedule: ScheduleInput) -> dict[str, np.ndarray]:
        """``signal`` (the counterbalanced choice), the interval's mode and the factors signal or noise set."""
        assert isinstance(response, YesNoResponse)
        signal = schedule.binary.astype(bool)
        return {"signal": signal, **interval_spec_columns(1, response.signal, response.noise, signal, schedule.columns)}

    def check(self, response: KindResponse, checks: Checks, path: Loc) -> None:
        """The level factor and every factor signal or noise sets are numeric; a mode factor names modes; signal
        and noise differ (else every trial looks the same)."""
        assert isinstance(response, YesNoResponse)
        check_specs(checks, path, {"signal": response.signal, "noise": response.noise}, response.level_factor)
        if response.signal == response.noise:
            checks.add(path + ("noise",), "signal and noise are the same stimulus, so no trial could be told apart; "
                                          "give noise another mode or a set: (e.g. set: {level_D: 0})")

    def check_observer(self, observer: ObserverBase, response: KindResponse, checks: Checks, path: Loc) -> None:
        if isinstance(observer, ImageObserver):  # answers from the interval's frames
            for name in unread_fields(observer, self.name):
                checks.add(path + (name,), f"the image observer's yes/no rule does not read {name}; remove it")
            return
        assert isinstance(observer, PsychometricYesNo) and isinstance(response, YesNoResponse)
        if checks.factor_exists(observer.level_column, path + ("level_column",), numeric=True) and \
                observer.level_column != response.level_factor:
            checks.add(path + ("level_column",), f"the observer reads '{observer.level_column}' as its level, but the "
                                                 f"response's level_factor is {response.level_factor!r}; set "
                                                 f"response.level_factor: {observer.level_column}")

    def score(self, row: TrialRow, answer: str) -> Scored:
        return Scored(correct=answer == ("yes" if bool(row["signal"]) else "no"))

    def targets(self, study: StudyInputs) -> list[AnalysisTarget]:
        """Rates, d' and criterion per condition (and "yes" fits) in results/, and their figure: one run of
        analysis/yes_no.py writes them all (as analysis/n_afc.py does)."""
        name = study.study
        return [AnalysisTarget(f"{name}_yes_no.png", "analysis/yes_no.py",
                               f"$(STATS_SRC) $(DRAW_SRC) {study.trials}", f"{study.common_arguments} --n-jobs $(JOBS)")]


KIND = YesNo()
