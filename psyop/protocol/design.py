"""Experimental design: factors and their levels, repetitions, practice, randomisation.

Factor names are schedule column names. A numeric factor must say its unit in its name
(``back_D``, ``target_fraction``); a factor of words (``mode``, ``rendering``, ``pair``) need not.
Levels are a list, a stepped range (``{start, step, count}``), levels that depend on another
factor's level (``depends_on`` + ``levels_by``), or ``adaptive`` (filled while the session runs).
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from psyop.protocol.base import Integer, Number, StrictModel

Level = Number | str


class SteppedLevels(StrictModel):
    """``count`` levels ``start, start + step, ...`` (e.g. the 0.45 D step set)."""

    start: Number
    step: Number = Field(gt=0)
    count: Integer = Field(ge=1, le=100000)

    def values(self) -> list[float]:
        # round to 12 decimals so that 3 * 0.45 is 1.35, not 1.3500000000000003
        return [round(self.start + i * self.step, 12) for i in range(self.count)]


class AdaptiveLevel(StrictModel):
    """A level chosen at run time by an adaptive procedure (psyop.adaptive; docs/adaptive.md).

    The schedule leaves the factor's column empty (NaN) and marks the trial ``adaptive``; before
    each trial the session asks the condition's procedure, rebuilt from the logged trials, for the
    level. An adaptive factor is not crossed: every condition of the other factors gets
    ``repetitions`` adaptive trials, randomly interleaved by the schedule (one procedure per
    condition). ``start`` is the first trial's level; levels stay within [min, max].

    - ``quest_plus``: QUEST+ (2AFC cumulative normal); ``grid_points`` levels/thresholds over
      [min, max] (default 101).
    - ``staircase``: ``rule`` 1u2d, 1u3d (default) or weighted (Kaernbach, ``target`` p correct,
      default 0.75); ``step_sizes`` after 0, 1, 2, ... reversals (default: range/10, /20, /40).

    Stopping: each condition runs at most ``repetitions`` trials; with ``target_sd`` (in the
    factor's unit) a condition stops as soon as its running estimate's SD is at most that
    (after at least ``min_trials`` counted trials, default 1) and its remaining trials are not run.
    """

    procedure: str = Field(min_length=1, description="quest_plus or staircase")
    start: Number
    min: Number
    max: Number
    grid_points: Integer | None = Field(default=None, ge=5, le=1001, description="quest_plus only")
    rule: Literal["1u2d", "1u3d", "weighted"] | None = Field(default=None, description="staircase only")
    step_sizes: list[Annotated[Number, Field(gt=0)]] | None = Field(default=None, min_length=1,
                                                                    description="staircase only")
    target: Number | None = Field(default=None, gt=0.5, lt=1, description="weighted staircase only")
    target_sd: Number | None = Field(default=None, gt=0, description="stop a condition once its estimate's SD "
                                                                     "is at most this (factor's unit)")
    min_trials: Integer | None = Field(default=None, ge=1, description="target_sd applies after this many trials")

    @model_validator(mode="after")
    def _range(self) -> "AdaptiveLevel":
        if not self.min <= self.start <= self.max or not self.min < self.max:
            raise ValueError("need min <= start <= max and min < max")
        staircase_only = [n for n in ("rule", "step_sizes", "target") if getattr(self, n) is not None]
        if self.procedure == "quest_plus" and staircase_only:
            raise ValueError(f"{', '.join(staircase_only)}: staircase settings; quest_plus does not use them")
        if self.procedure == "staircase" and self.grid_points is not None:
            raise ValueError("grid_points is a quest_plus setting; a staircase does not use it")
        if self.target is not None and self.rule != "weighted":
            raise ValueError("target is the weighted staircase's p(correct); give rule: weighted or drop target")
        if self.min_trials is not None and self.target_sd is None:
            raise ValueError("min_trials delays the target_sd stop; give target_sd or drop min_trials")
        # the uniform prior on [min, max] of both procedures' estimate (a staircase's is QUEST+'s posterior)
        prior_sd = (float(self.max) - float(self.min)) / 12 ** 0.5
        if self.target_sd is not None and self.target_sd >= prior_sd:
            raise ValueError(f"target_sd {self.target_sd:g} is not below the SD of the estimate's uniform prior over "
                             f"[min, max] ({prior_sd:.3g}): it would stop before learning anything; give a smaller one")
        return self


class Factor(StrictModel):
    """One independent variable. Give exactly one of ``levels``, ``levels_by`` or ``adaptive``."""

    levels: list[Level] | SteppedLevels | None = None
    depends_on: str | None = None
    levels_by: dict[Number | str, list[Level] | SteppedLevels] | None = None
    adaptive: AdaptiveLevel | None = None
    description: str | None = None

    @model_validator(mode="after")
    def _one_source(self) -> "Factor":
        given = [n for n in ("levels", "levels_by", "adaptive") if getattr(self, n) is not None]
        if len(given) != 1:
            raise ValueError("give exactly one of: levels (a list or {start, step, count}), "
                             "depends_on + levels_by, or adaptive")
        if (self.levels_by is None) != (self.depends_on is None):
            raise ValueError("levels_by and depends_on go together: levels_by maps each level of the "
                             "depends_on factor to this factor's levels")
        for values in self.level_sets():
            if not values:
                raise ValueError("a factor needs at least one level")
            if len({(type(v) is str, v) for v in values}) != len(values):
                raise ValueError(f"levels repeat: {values}; each level must be listed once")
            if len({type(v) is str for v in values}) != 1:
                raise ValueError("levels mix numbers and words; use one kind")
        return self

    def level_sets(self) -> list[list[Level]]:
        """Every list of levels this factor can take (one, or one per parent level)."""
        if self.levels is not None:
            return [_values(self.levels)]
        if self.levels_by is not None:
            return [_values(v) for v in self.levels_by.values()]
        return []

    def all_levels(self) -> list[Level]:
        """Every distinct level this factor can take, in first-seen order ([] when adaptive)."""
        seen: list[Level] = []
        for values in self.level_sets():
            seen += [v for v in values if v not in seen]
        return seen

    def levels_for(self, parent_level: Level | None) -> list[Level]:
        """This factor's levels, given the parent's level when it depends on one."""
        if self.levels is not None:
            return _values(self.levels)
        assert self.levels_by is not None
        for key, value in self.levels_by.items():
            if _same_level(key, parent_level):
                return _values(value)
        raise KeyError(parent_level)

    @property
    def is_numeric(self) -> bool:
        if self.adaptive is not None:
            return True
        return all(not isinstance(v, str) for values in self.level_sets() for v in values)


def _values(levels: list[Level] | SteppedLevels) -> list[Level]:
    if isinstance(levels, SteppedLevels):
        return list(levels.values())
    return list(levels)


def _same_level(a: Level | None, b: Level | None) -> bool:
    if isinstance(a, str) or isinstance(b, str) or a is None or b is None:
        return a == b
    return abs(float(a) - float(b)) <= 1e-9 * max(1.0, abs(float(a)))


class Randomisation(StrictModel):
    """Trial order. ``full``: all trials shuffled. ``blocked``: one block per combination of the
    ``by`` factors, trials shuffled within blocks, blocks in ``block_order``: ``random`` (drawn from
    the session's seed), ``fixed`` (as written) or ``latin_square`` (a Williams design keyed to the
    participant index, balanced for first-order carry-over; psyop.schedule.counterbalance). ``sequential``:
    conditions in protocol order, repetitions last (pilots and debugging only)."""

    kind: Literal["full", "blocked", "sequential"] = "full"
    by: list[str] = Field(default_factory=list)
    block_order: Literal["random", "fixed", "latin_square"] = "random"

    @model_validator(mode="after")
    def _by(self) -> "Randomisation":
        if self.kind == "blocked" and not self.by:
            raise ValueError("blocked randomisation needs by: [factor, ...]")
        if self.kind != "blocked" and self.by:
            raise ValueError("by: only applies to kind: blocked")
        if self.kind != "blocked" and self.block_order != "random":
            raise ValueError(f"block_order: {self.block_order} only applies to kind: blocked (with by: [factor, ...])")
        return self


class Design(StrictModel):
    """Factors are fully crossed (dependent levels nested in their parent); every condition is
    repeated ``repetitions`` times. ``practice_trials`` extra trials (drawn at random from the
    conditions, flagged ``practice``) come first."""

    factors: dict[str, Factor] = Field(min_length=1)
    repetitions: Integer = Field(ge=1, le=1000000)
    practice_trials: Integer = Field(default=0, ge=0, le=1000)
    randomisation: Randomisation = Field(default_factory=Randomisation)

    @model_validator(mode="after")
    def _bounded(self) -> "Design":
        # counted from the factor sizes, before anything is expanded (two factors of 100000
        # levels used to reach 8 GB before a cap on the expanded list was checked)
        n = count_conditions(self.factors, MAX_CONDITIONS)
        if n is not None and n > MAX_CONDITIONS:
            raise ValueError(f"the factors cross to over {MAX_CONDITIONS} conditions; reduce their levels")
        if n is not None and n * self.repetitions > MAX_TRIALS:
            raise ValueError(f"{n} conditions x {self.repetitions} repetitions is over {MAX_TRIALS} trials; "
                             "reduce the factors' levels or the repetitions")
        return self


#: the most trials a protocol may schedule, checked before conditions are expanded: it bounds
#: validate/compile memory (1 million trials compile in under 0.6 GB; a session of them would
#: take weeks)
MAX_TRIALS = 1_000_000
#: the most crossed conditions (each is a dict while validating)
MAX_CONDITIONS = 100_000


def _n_levels(levels: list[Level] | SteppedLevels) -> int:
    return levels.count if isinstance(levels, SteppedLevels) else len(levels)


def count_conditions(factors: dict[str, Factor], limit: int) -> int | None:
    """How many conditions crossing ``factors`` gives, without expanding them.

    Stops early and returns ``limit + 1`` once the count is known to exceed ``limit``;
    returns None when the dependencies cannot be resolved (reported by the protocol checks).
    Only the levels of factors that others depend on are tracked individually.
    """
    order: list[str] = []
    remaining = dict(factors)
    while remaining:
        ready = [n for n, f in remaining.items() if f.depends_on is None or f.depends_on in order]
        if not ready:
            return None
        for name in ready:
            order.append(name)
            del remaining[name]
    parents = {f.depends_on for f in factors.values() if f.depends_on}
    tracked: list[str] = []
    states: dict[tuple[Level, ...], int] = {(): 1}
    for name in order:
        factor = factors[name]
        grown: dict[tuple[Level, ...], int] = {}
        for state, multiplicity in states.items():
            if factor.adaptive is not None:
                options: list[Level] | None = None
                n_levels = 1
            elif factor.levels is not None:
                options, n_levels = None, _n_levels(factor.levels)
            else:
                parent_level = state[tracked.index(factor.depends_on)] if factor.depends_on in tracked else None
                match = [v for k, v in (factor.levels_by or {}).items() if _same_level(k, parent_level)]
                if not match:
                    return None
                options, n_levels = None, _n_levels(match[0])
                if name in parents:
                    options = list(_values(match[0]))
            if name in parents:
                values = options if options is not None else (
                    [float("nan")] if factor.adaptive is not None else _values(factor.levels))  # type: ignore[arg-type]
                for value in values:
                    key = state + (value,)
                    grown[key] = grown.get(key, 0) + multiplicity
                    if len(grown) > limit:
                        return limit + 1
            else:
                grown[state] = grown.get(state, 0) + multiplicity * n_levels
        if name in parents:
            tracked.append(name)
        states = grown
        total = sum(states.values())
        if total > limit:
            return limit + 1
    return sum(states.values())
