"""What several kinds share about the stimuli they show: each trial's rendering mode (a fixed mode or a factor whose
levels are modes) and interval specs (a mode and factor overrides, ``{mode, set: {factor: value}}``): the factors
they read, their checks, and the schedule columns of an interval that shows one spec or another."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from psyop.protocol.kinds.base import Checks, IntervalSpec, ModeFromFactor, mode_factor_of
from psyop.protocol.scene import RenderingMode
from psyop.records import Loc


def mode_values(mode: RenderingMode | ModeFromFactor, columns: Mapping[str, np.ndarray], n: int) -> np.ndarray:
    """Each trial's mode: the factor's column, or ``mode`` in every trial."""
    if isinstance(mode, ModeFromFactor):
        return columns[mode.factor].astype(object)
    return np.full(n, mode, dtype=object)


def specs_factors(specs: tuple[IntervalSpec, ...], level_factor: str | None = None) -> set[str]:
    """The factors some specs read: their mode factors, their ``set:`` keys, and the level factor (if any)."""
    used = set() if level_factor is None else {level_factor}
    for spec in specs:
        used |= mode_factor_of(spec.mode) | set(spec.set)
    return used


def check_specs(checks: Checks, path: Loc, specs: Mapping[str, IntervalSpec], level_factor: str | None = None) -> None:
    """The level factor and every factor a spec sets are numeric factors; a mode factor's levels are modes (each
    issue at its key under ``path``: ``level_factor``, ``<role>.set.<factor>``, ``<role>.mode.factor``)."""
    if level_factor is not None:
        checks.factor_exists(level_factor, path + ("level_factor",), numeric=True)
    for role, spec in specs.items():
        for key in spec.set:
            checks.factor_exists(key, path + (role, "set", key), numeric=True)
        if isinstance(spec.mode, ModeFromFactor):
            checks.mode_factor(spec.mode.factor, path + (role, "mode", "factor"))


def interval_spec_columns(interval: int, shown: IntervalSpec, other: IntervalSpec, shows: np.ndarray,
                          columns: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Interval ``interval``'s ``mode_interval<k>`` and ``<factor>_interval<k>`` columns: the ``shown`` spec in the
    trials where ``shows`` is true, ``other`` elsewhere (a factor neither spec sets keeps the trial's level)."""
    n = shows.size
    out = {f"mode_interval{interval}": np.where(shows, mode_values(shown.mode, columns, n),
                                                mode_values(other.mode, columns, n))}
    for name in sorted(set(shown.set) | set(other.set)):
        value = [np.full(n, spec.set[name], dtype=np.float64) if name in spec.set else
                 np.asarray(columns[name], dtype=np.float64) for spec in (shown, other)]
        out[f"{name}_interval{interval}"] = np.where(shows, value[0], value[1])
    return out
