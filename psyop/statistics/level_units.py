"""A psychometric fit table's level-valued columns named in the unit of the level they were fitted over.

psyop.statistics.psychometric computes in the level's own numbers and names its level-valued columns with
``_D`` (the paper's levels are diopters). A study whose ``level_factor`` is another quantity (a contrast
fraction, a log10 contrast, a latency in ms) writes its results with those columns renamed to the level
factor's unit suffix (psyop.protocol.base.UNIT_SUFFIXES): ``threshold_D`` becomes ``threshold_fraction`` for
``contrast_fraction``, ``threshold_ms`` for ``added_latency_ms``. A level factor without a unit suffix gives
``_level`` (``threshold_level``): never a unit the numbers do not have.

Examples
--------
>>> level_suffix("level_D"), level_suffix("contrast_fraction"), level_suffix("contrast_log10"), level_suffix("n")
('_D', '_fraction', '_log10', '_level')
>>> import pandas as pd
>>> list(in_level_units(pd.DataFrame({"threshold_D": [0.1], "lapse": [0.0]}), "added_latency_ms"))
['threshold_ms', 'lapse']
"""

from __future__ import annotations

import pandas as pd

from psyop.protocol.base import UNIT_SUFFIXES

#: the fit table's columns whose values are levels (or level differences), named with ``_D``
LEVEL_VALUED = ("threshold_D", "threshold_ci_low_D", "threshold_ci_high_D", "threshold_bound_D", "width_D",
                "sigma_D", "location_D", "level_min_D", "level_max_D", "ci_width_D")
#: the suffix of a level factor without a unit suffix
NO_UNIT = "_level"


def level_suffix(level_factor: str) -> str:
    """The unit suffix of ``level_factor``'s name (the longest of UNIT_SUFFIXES it ends with), else ``_level``."""
    matches = [suffix for suffix in UNIT_SUFFIXES if level_factor.endswith(suffix)]
    return max(matches, key=len) if matches else NO_UNIT


def level_unit_text(level_factor: str) -> str:
    """The unit as a reader sees it after a number: ``D``, ``ms``, ``log10``; the factor's name when it has none."""
    suffix = level_suffix(level_factor)
    return level_factor if suffix == NO_UNIT else suffix[1:]


def renamed_columns(level_factor: str) -> dict[str, str]:
    """``{"threshold_D": "threshold<suffix>", ...}`` for the level-valued columns; empty for a level in diopters."""
    suffix = level_suffix(level_factor)
    return {} if suffix == "_D" else {name: name[: -len("_D")] + suffix for name in LEVEL_VALUED}


def in_level_units(table: pd.DataFrame, level_factor: str) -> pd.DataFrame:
    """``table`` with its level-valued columns named in ``level_factor``'s unit (a copy; other columns kept)."""
    return table.rename(columns=renamed_columns(level_factor))
