"""Readable names for code names in figures, and the figure text style (>= 9 pt at saved size)."""

from __future__ import annotations

from matplotlib.typing import RcKeyType

#: matplotlib rc settings every psyop figure is drawn under (``plt.rc_context(STYLE)``): no text
#: below 9 pt at the saved size (figures are saved at 1:1, ``bbox_inches='tight'``).
STYLE: dict[RcKeyType, object] = {
    "font.size": 10, "axes.titlesize": 11, "axes.labelsize": 10, "xtick.labelsize": 9, "ytick.labelsize": 9,
    "legend.fontsize": 9, "figure.titlesize": 11,
}

MODE_LABELS = {
    "conventional": "conventional", "ocular": "ocular parallax", "reversed": "reversed ocular parallax",
    "enabled": "ocular parallax enabled", "disabled": "ocular parallax disabled",
}
CONDITION_LABELS = {"back_D": "back surface at {v:g} D", "offset_D": "offset {v:g} D", "separation_D": "separation {v:g} D"}


def mode_label(mode: str) -> str:
    """'ocular' -> 'ocular parallax'; unknown names pass through with underscores as spaces."""
    return MODE_LABELS.get(str(mode), str(mode).replace("_", " "))


def condition_label(column: str, value: object) -> str:
    """('back_D', 1.0) -> 'back surface at 1 D'; a level of words as it is: ('mode', 'ocular') -> 'mode ocular'.

    Examples
    --------
    >>> condition_label("back_D", 1.0), condition_label("mode", "ocular"), condition_label("size_deg", 2.5)
    ('back surface at 1 D', 'mode ocular', 'size deg 2.5')
    """
    from psyop.statistics.conditions import CELL_COLUMN, level_text

    template = CONDITION_LABELS.get(column)
    if template and isinstance(value, (int, float)):
        return template.format(v=value)
    return level_text(value) if column == CELL_COLUMN else f"{column.replace('_', ' ')} {level_text(value)}"


def participant_label(participant: str) -> str:
    """'S01' / '01' -> 'participant S01' / 'participant 01' (never 'sub-S01')."""
    return f"participant {participant}"


DISPLAY_LABELS = {"vive_pro": "HTC Vive Pro"}


def display_label(name: str) -> str:
    """'vive_pro' -> 'HTC Vive Pro'."""
    return DISPLAY_LABELS.get(name, name.replace("_", " "))
