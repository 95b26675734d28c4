"""``two_interval``: which of two intervals showed more (two-interval forced choice; detection and
discrimination). Columns ``mode_interval1/2``, ``correct_interval``, the level column and
``<factor>_interval1/2`` for the factors an interval overrides; a psychometric fit per condition."""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar, Literal

import numpy as np
from pydantic import Field, model_validator

from psyop.protocol.base import Number, format_level
from psyop.errors import UserError
from psyop.protocol.kinds.base import (AnalysisTarget, Checks, Counterbalance, IntervalSpec, KindResponse,
                                       ModeFromFactor, ObserverBase, ResponseKindSpec, ScheduleInput, Scored,
                                       StudyInputs, mode_factor_of, normal_cdf)
from psyop.protocol.kinds.modes import mode_values
from psyop.protocol.image_observer import ImageObserver, unread_fields
from psyop.records import Loc, TrialRow


class TwoIntervalResponse(KindResponse):
    """Two-interval forced choice; the ``test`` interval is the correct answer."""

    kind: Literal["two_interval"]
    intervals_needed: ClassVar[int] = 2
    question: str = "Which interval showed more relative motion?"
    test: IntervalSpec
    reference: IntervalSpec
    level_factor: str = "level_D"
    order: Counterbalance = "balanced"
    #: conditions whose two intervals are meant to render identically (a control): each factor -> level
    identical_intervals: list[dict[str, Number | str]] = Field(default_factory=list)

    @property
    def counterbalance(self) -> Counterbalance:
        """How the interval order (test first or second) is assigned."""
        return self.order

    def identical_conditions(self) -> list[dict[str, str | float]]:
        return [{k: (v if isinstance(v, str) else float(v)) for k, v in d.items()} for d in self.identical_intervals]

    def level(self) -> str | None:
        return self.level_factor

    def interval_specs(self) -> tuple[IntervalSpec, ...]:
        """The intervals' specs: (test, reference)."""
        return (self.test, self.reference)

    def factors_read(self) -> set[str]:
        """The factors this response reads: the level, each interval's mode factor and ``set:`` keys."""
        used = {self.level_factor}
        for spec in self.interval_specs():
            used |= mode_factor_of(spec.mode) | set(spec.set)
        return used


class Psychometric2afc(ObserverBase):
    """p(correct) = 0.5 + (0.5 - lapse) * Phi((level - t) / width_D + z75), where t, the 75 % point (without lapse),
    is threshold_D + threshold_slope * row[threshold_offset_column] (a factor of numbers) or threshold_D +
    threshold_offset_D[the row's level of threshold_offset_column] (any factor: a mode effect,
    ``{ocular: 0, reversed: 0.3}``); each simulated participant's threshold is shifted by N(0, between_subject_sd_D)."""

    kind: Literal["psychometric_2afc"]
    level_column: str = "level_D"
    threshold_D: Number = Field(description="the 75 % point in the level's unit (negative on a log axis, e.g. "
                                            "log10 contrast)")
    width_D: Number = Field(gt=0)
    lapse: Number = Field(default=0.0, ge=0, lt=0.5)
    threshold_slope: Number = 0.0
    threshold_offset_column: str | None = None
    threshold_offset_D: dict[str, Number] | None = Field(default=None, min_length=1)
    between_subject_sd_D: Number = Field(default=0.0, ge=0)
    declared: ClassVar[bool] = True

    @model_validator(mode="after")
    def _offset(self) -> "Psychometric2afc":
        if self.threshold_slope != 0.0 and self.threshold_offset_column is None:
            raise ValueError("threshold_slope needs threshold_offset_column (the column it multiplies)")
        if self.threshold_offset_D is not None and self.threshold_offset_column is None:
            raise ValueError("threshold_offset_D needs threshold_offset_column (the factor whose levels it keys)")
        if self.threshold_offset_D is not None and self.threshold_slope != 0.0:
            raise ValueError("give threshold_slope (a factor of numbers) or threshold_offset_D (an offset per level), "
                             "not both")
        return self

    def participant_draws(self, rng: np.random.Generator) -> dict[str, float]:
        """The participant's threshold shift ``participant_shift_D`` ~ N(0, between_subject_sd_D)."""
        sd = float(self.between_subject_sd_D)
        return {"participant_shift_D": float(rng.normal(0.0, sd)) if sd > 0 else 0.0}

    def threshold_for(self, row: TrialRow, participant: Mapping[str, float]) -> float:
        """The participant's 75 % point in trial ``row`` (its offset column's slope or per-level offset)."""
        base = float(self.threshold_D) + participant["participant_shift_D"]
        column = self.threshold_offset_column
        if column and self.threshold_offset_D is not None:
            level = format_level(row[column])
            if level not in self.threshold_offset_D:
                raise UserError(f"observer: threshold_offset_D has no offset for {column} = {level}",
                                "protocol observer")
            return base + float(self.threshold_offset_D[level])
        offset = float(row[column]) if column else 0.0
        return base + float(self.threshold_slope) * offset

    def probability(self, row: TrialRow, participant: Mapping[str, float]) -> float:
        """p(correct) in trial ``row``."""
        z = (float(row[self.level_column]) - self.threshold_for(row, participant)) / float(self.width_D)
        return 0.5 + (0.5 - float(self.lapse)) * normal_cdf(z)

    def answer(self, row: TrialRow, participant: Mapping[str, float], u: float) -> str:
        """The correct interval when ``u < p``, else the other."""
        right = int(row["correct_interval"])
        return str(right if u < self.probability(row, participant) else 3 - right)


def interval_columns(test: IntervalSpec, reference: IntervalSpec, schedule: ScheduleInput, test_first: np.ndarray
                     ) -> dict[str, np.ndarray]:
    """Each interval's mode, the correct interval and the factors an interval overrides, per interval."""
    out: dict[str, np.ndarray] = {}
    columns, n = schedule.columns, schedule.n
    test_mode = mode_values(test.mode, columns, n)
    reference_mode = mode_values(reference.mode, columns, n)
    out["mode_interval1"] = np.where(test_first, test_mode, reference_mode)
    out["mode_interval2"] = np.where(test_first, reference_mode, test_mode)
    out["correct_interval"] = np.where(test_first, 1, 2).astype(np.int64)
    for name in sorted(set(test.set) | set(reference.set)):
        test_value = np.full(n, test.set[name]) if name in test.set else columns[name]
        ref_value = np.full(n, reference.set[name]) if name in reference.set else columns[name]
        out[f"{name}_interval1"] = np.where(test_first, test_value, ref_value).astype(np.float64)
        out[f"{name}_interval2"] = np.where(test_first, ref_value, test_value).astype(np.float64)
    return out


class TwoInterval(ResponseKindSpec):
    name = "two_interval"
    former_names = ("2afc_interval",)
    label = "two-interval"
    takes_confidence = True  # one discrete choice: a confidence rating may follow
    model = TwoIntervalResponse
    observer_models = (Psychometric2afc, ImageObserver)
    keys = {"1": "1", "2": "2", "left": "1", "right": "2", "kp_1": "1", "kp_2": "2"}
    buttons = {"1": "1", "2": "2", "L": "1", "R": "2"}
    controller = {"left": "1", "right": "2"}
    answer_labels = {"1": "first interval", "2": "second interval"}
    fields = {"TwoIntervalResponse": {"kind": "plan", "question": "plan", "test": "kinds", "reference": "kinds",
                                      "level_factor": "plan", "order": "kinds", "identical_intervals": "kinds"},
              "Psychometric2afc": {k: "kinds" for k in ("kind", "level_column", "threshold_D", "width_D", "lapse",
                                                           "threshold_slope", "threshold_offset_column",
                                                           "threshold_offset_D", "between_subject_sd_D")},
              "ImageObserver": {k: "image_observer" for k in ImageObserver.model_fields if k != "eye"}}

    def columns(self, response: KindResponse, schedule: ScheduleInput) -> dict[str, np.ndarray]:
        assert isinstance(response, TwoIntervalResponse)
        # binary False: the test stimulus comes first
        return interval_columns(response.test, response.reference, schedule, ~schedule.binary)

    def check(self, response: KindResponse, checks: Checks, path: Loc) -> None:
        """The level factor and every factor an interval sets are numeric factors; a mode factor names modes."""
        assert isinstance(response, TwoIntervalResponse)
        checks.factor_exists(response.level_factor, path + ("level_factor",), numeric=True)
        for role, spec in (("test", response.test), ("reference", response.reference)):
            for key in spec.set:
                checks.factor_exists(key, path + (role, "set", key), numeric=True)
            if isinstance(spec.mode, ModeFromFactor):
                checks.mode_factor(spec.mode.factor, path + (role, "mode", "factor"))
        self.check_identical(response, checks, path)

    def check_identical(self, response: TwoIntervalResponse, checks: Checks, path: Loc) -> None:
        """Each declared control names design factors and levels they have."""
        for index, declared in enumerate(response.identical_intervals):
            for name, level in declared.items():
                where = path + ("identical_intervals", index, name)
                if checks.factor_exists(name, where) and not any(
                        format_level(level) == format_level(have) for have in checks.factors[name].all_levels()):
                    checks.add(where, f"'{format_level(level)}' is not a level of {name}")

    def check_design(self, response: KindResponse, checks: Checks) -> None:
        """A threshold needs its level to vary: a fixed level factor needs at least two levels in every level
        set (else every fit is ``no_fit`` after a full session)."""
        assert isinstance(response, TwoIntervalResponse)
        if response.level_factor not in checks.factors:
            return
        factor = checks.factors[response.level_factor]
        for values in factor.level_sets():
            if len(values) < 2:
                key = "levels_by" if factor.levels_by is not None else "levels"
                checks.add(("design", "factors", response.level_factor, key),
                           f"the level factor '{response.level_factor}' has one level ({values[0]!r}) here: a threshold "
                           "needs the level to vary; give at least two levels (five or more for a psychometric fit, "
                           "e.g. {start: 0, step: 0.25, count: 5}) or make it adaptive")
                return

    def check_observer(self, observer: ObserverBase, response: KindResponse, checks: Checks, path: Loc) -> None:
        if isinstance(observer, ImageObserver):  # answers from the frames: nothing of the schedule to check
            for name in unread_fields(observer, self.name):
                checks.add(path + (name,), f"the image observer's two-interval rule does not read {name}; remove it")
            return
        assert isinstance(observer, Psychometric2afc) and isinstance(response, TwoIntervalResponse)
        level_factor = response.level_factor
        if checks.factor_exists(observer.level_column, path + ("level_column",), numeric=True) and \
                observer.level_column != level_factor:
            checks.add(path + ("level_column",), f"the observer reads '{observer.level_column}' as its level, but "
                                                 f"the response's level factor is '{level_factor}'; set level_column: "
                                                 f"{level_factor}")
        column = observer.threshold_offset_column
        if column is None:
            return
        if observer.threshold_offset_D is None:  # threshold_slope x the column's value: numbers
            checks.factor_exists(column, path + ("threshold_offset_column",), numeric=True)
        elif checks.factor_exists(column, path + ("threshold_offset_column",)):
            given = set(observer.threshold_offset_D)
            for level in checks.factors[column].all_levels():
                if format_level(level) not in given:
                    checks.add(path + ("threshold_offset_D",), f"no offset for {column} = {format_level(level)}; add "
                                                               f"'{format_level(level)}: 0' under threshold_offset_D")

    def score(self, row: TrialRow, answer: str) -> Scored:
        return Scored(correct=answer == str(int(row["correct_interval"])))

    def targets(self, study: StudyInputs) -> list[AnalysisTarget]:
        """The fits, threshold figure, psychometric panels and (adaptive) track plot. A level in log10 Michelson
        contrast (a ``*_log10`` level factor) gets its thresholds as contrasts and in dB (analysis/contrast_detection.py)
        instead of the threshold figure, which reads levels as non-negative (dioptres, milliseconds)."""
        name, trials, common = study.study, study.trials, study.common_arguments
        fits = f"$(RESULTS)/{name}_fits.csv"
        script = "analysis/fig_discrimination_thresholds.py" if study.linear_fit else \
            "analysis/fig_detection_thresholds.py"
        log_contrast = (study.level_factor or "").endswith("_log10")
        thresholds = AnalysisTarget(f"{name}_contrast_thresholds.png", "analysis/contrast_detection.py",
                                    f"{fits} $(DRAW_SRC)", f'{common} --fits "{fits}"') if log_contrast else \
            AnalysisTarget(f"{name}_thresholds.png", script, f"{fits} $(DRAW_SRC)", f'{common} --fits "{fits}"')
        return [AnalysisTarget(f"{name}_fits.csv", "analysis/fit_psychometric.py", f"$(STATS_SRC) {trials}",
                               f"{common} --n-jobs $(JOBS)", kind="fits"), thresholds,
                AnalysisTarget(f"supp_psychometric_{name}.png", "analysis/supp_psychometric_functions.py",
                               f"{fits} $(DRAW_SRC)", f'{common} --fits "{fits}"')] + ([
                AnalysisTarget(f"{name}_tracks.png", "analysis/adaptive_tracks.py",
                               f"{fits} {trials} $(DRAW_SRC) psyop/figures/adaptive_figures.py",
                               f'{common} --fits "{fits}"')] if study.adaptive else [])


KIND = TwoInterval()
