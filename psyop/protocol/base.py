"""Shared building blocks for protocol models: strict frozen base model, numbers, unit suffixes."""

from __future__ import annotations

import math
from typing import Annotated, Any

from pydantic import AfterValidator, BaseModel, BeforeValidator, ConfigDict

#: Suffixes a numeric factor name must end with, so that every column says its unit.
UNIT_SUFFIXES: tuple[str, ...] = ("_D", "_m", "_mm", "_deg", "_rad", "_s", "_ms", "_px", "_arcmin", "_hz", "_fraction",
                                  "_percent", "_count", "_cd_m2", "_log10")


class StrictModel(BaseModel):
    """Base of every protocol model: unknown keys are errors, instances are immutable."""

    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=False)


def _no_bool(value: Any) -> Any:  # Any: pydantic validator input
    # YAML `yes`/`true` would otherwise silently become 1.0.
    if isinstance(value, bool):
        raise ValueError("expected a number, got a boolean (true/false); write a number such as 1 or 0.5")
    return value


def _finite(value: float) -> float:
    if not math.isfinite(value):
        raise ValueError("expected a finite number (not .inf or .nan)")
    return value


#: A finite float that refuses booleans.
Number = Annotated[float, BeforeValidator(_no_bool), AfterValidator(_finite)]
#: An int that refuses booleans.
Integer = Annotated[int, BeforeValidator(_no_bool)]


def has_unit_suffix(name: str) -> bool:
    """True when ``name`` ends with one of :data:`UNIT_SUFFIXES`."""
    return name.endswith(UNIT_SUFFIXES)


def format_level(value: float | str) -> str:
    """Shortest stable text for a factor level, used in condition labels (``0.45``, ``1``, ``ocular``)."""
    if isinstance(value, str):
        return value
    text = repr(float(value))
    return text[:-2] if text.endswith(".0") else text
