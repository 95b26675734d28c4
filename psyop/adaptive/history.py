"""What a procedure sees: the (level, response) history of its own condition, oldest first."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Observation:
    """One finished trial: the level shown and whether the response was correct."""

    level: float
    correct: bool

    def __post_init__(self) -> None:
        if not math.isfinite(self.level):
            raise ValueError(f"observation level must be finite, got {self.level!r}")
