"""Reading one trial row the way a stimulus needs it: per-interval values."""

from __future__ import annotations

from psyop.records import JsonObject, TrialRow


def interval_values(row: TrialRow, interval: int) -> JsonObject:
    """The row as seen during interval ``interval`` (1-based).

    ``<name>_interval<k>`` columns (factor overrides of a two-interval response, e.g. the
    discrimination reference's ``level_D = 0``) replace ``<name>``, and ``mode`` is that
    interval's rendering mode. Depths resolve against the result, e.g.
    ``primitive.depth.resolve_D(interval_values(row, 2))``.
    """
    if interval < 1:
        raise ValueError(f"intervals are numbered from 1, got {interval}")
    suffix = f"_interval{interval}"
    values = {key: value for key, value in row.items() if "_interval" not in str(key)}
    for key, value in row.items():
        if str(key).endswith(suffix):
            values[str(key)[: -len(suffix)]] = value
    return values


#: The rendering modes a ``mode_interval<k>`` column may hold.
RENDERING_MODES: tuple[str, ...] = ("conventional", "ocular", "reversed")


def mode_column(interval: int) -> str:
    """The schedule column holding interval ``interval``'s rendering mode (every response kind)."""
    if interval < 1:
        raise ValueError(f"intervals are numbered from 1, got {interval}")
    return f"mode_interval{interval}"


def interval_mode(row: TrialRow, interval: int) -> str:
    """The rendering mode of interval ``interval`` (1-based) of a trial row: the one
    interval-to-mode rule (the schedule compiler has already applied a reach study's ``modes:``)."""
    column = mode_column(interval)
    if column not in row:
        raise KeyError(f"trial row has no {column} column (schedules from psyop.schedule.compile_schedule have it)")
    value = str(row[column])
    if value not in RENDERING_MODES:
        raise ValueError(f"trial {row.get('trial')}: {column} is {value!r}, not a rendering mode "
                         f"({', '.join(RENDERING_MODES)})")
    return value
