"""The rendering mode of each trial, from a fixed mode or a factor whose levels are modes (shared by kinds)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from psyop.protocol.kinds.base import ModeFromFactor
from psyop.protocol.scene import RenderingMode


def mode_values(mode: RenderingMode | ModeFromFactor, columns: Mapping[str, np.ndarray], n: int) -> np.ndarray:
    """Each trial's mode: the factor's column, or ``mode`` in every trial."""
    if isinstance(mode, ModeFromFactor):
        return columns[mode.factor].astype(object)
    return np.full(n, mode, dtype=object)
