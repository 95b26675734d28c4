"""Expand a design's factors into its conditions (one mapping of factor -> level each).

Factors are crossed in the order they are written; a factor that ``depends_on`` another is
nested inside its parent's level. Adaptive factors are not crossed (their value is NaN).
"""

from __future__ import annotations

import math

from psyop.protocol.base import format_level
from psyop.protocol.design import Design, Level
from psyop.records import JsonObject


def factor_order(design: Design) -> list[str]:
    """Factor names with every parent before its dependants (otherwise in written order).

    Assumes dependencies were checked (no unknown parent, no cycle)."""
    order: list[str] = []
    pending = list(design.factors)
    while pending:
        progressed = False
        for name in list(pending):
            parent = design.factors[name].depends_on
            if parent is None or parent in order:
                order.append(name)
                pending.remove(name)
                progressed = True
        if not progressed:
            raise ValueError(f"factors depend on each other in a cycle: {pending}")
    return order


def expand_conditions(design: Design) -> list[dict[str, Level]]:
    """Every condition, in a stable order: the first written factor varies slowest."""
    order = factor_order(design)
    conditions: list[dict[str, Level]] = [{}]
    for name in order:
        factor = design.factors[name]
        expanded: list[dict[str, Level]] = []
        for condition in conditions:
            if factor.adaptive is not None:
                expanded.append({**condition, name: math.nan})
                continue
            parent_level = condition.get(factor.depends_on) if factor.depends_on else None
            for level in factor.levels_for(parent_level):
                expanded.append({**condition, name: level})
        conditions = expanded
    written = list(design.factors)
    return [{name: c[name] for name in written} for c in conditions]


def condition_label(condition: JsonObject, design: Design) -> str:
    """``back_D=1|level_D=0.25``: crossed (non-adaptive) factors in written order."""
    return "|".join(f"{name}={format_level(condition[name])}" for name, factor in design.factors.items()
                    if factor.adaptive is None)
