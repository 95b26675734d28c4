"""Scene fields given as ``{factor: NAME}``: where they are, and the scene item with the trial's values.

A size or a contrast (psyop.protocol.scene.Factorable) can be a factor's level. The stimulus builder
calls :func:`resolve_factor_fields` on each item with the trial's (interval's) values, so everything
downstream sees plain numbers; validation (psyop.protocol.semantics) resolves every item for every
condition and re-validates it, so a level outside a field's range is refused at its file:line.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

from pydantic import BaseModel

from psyop.protocol.scene import Depth, FactorRef
from psyop.records import JsonMapping, Loc


def factor_fields(value: object, path: Loc = ()) -> Iterator[tuple[Loc, FactorRef]]:
    """Every ``{factor: NAME}`` inside ``value`` (a scene item), with its key path below it.

    Examples
    --------
    >>> from psyop.protocol.scene import Disc
    >>> disc = Disc(id="t", kind="disc", size_deg={"factor": "size_deg"}, depth={"D": 1},
    ...             surface={"kind": "white_noise", "contrast": {"factor": "contrast_fraction"}})
    >>> [(p, r.factor) for p, r in factor_fields(disc)]
    [(('size_deg',), 'size_deg'), (('surface', 'contrast'), 'contrast_fraction')]
    """
    if isinstance(value, FactorRef):
        yield path, value
    elif isinstance(value, Depth):
        return
    elif isinstance(value, BaseModel):
        for name in type(value).model_fields:
            yield from factor_fields(getattr(value, name), path + (name,))
    elif isinstance(value, (list, tuple)):
        for index, item in enumerate(value):
            yield from factor_fields(item, path + (index,))


def resolve_factor_fields(value: Any, values: JsonMapping) -> Any:  # Any: a scene item or any field value in it
    """``value`` with every ``{factor: NAME}`` replaced by ``float(values[NAME])`` (unchanged, the same
    object, when it has none). A missing or non-finite value is a ValueError naming the factor.

    Examples
    --------
    >>> from psyop.protocol.scene import Disc
    >>> disc = Disc(id="t", kind="disc", size_deg={"factor": "size_deg"}, depth={"D": 1},
    ...             surface={"kind": "solid", "rgb": [1, 1, 1]})
    >>> resolve_factor_fields(disc, {"size_deg": 3.0}).size_deg
    3.0
    """
    if isinstance(value, FactorRef):
        if value.factor not in values:
            raise ValueError(f"the trial has no value of factor {value.factor!r}")
        number = float(values[value.factor])
        if not math.isfinite(number):
            raise ValueError(f"factor {value.factor!r} has no level for this trial ({number}); an adaptive "
                             "level is known only while the session runs (psyop render --level)")
        return number
    if isinstance(value, Depth) or not isinstance(value, (BaseModel, list, tuple)):
        return value
    if isinstance(value, BaseModel):
        updates = {}
        for name in type(value).model_fields:
            field = getattr(value, name)
            new = resolve_factor_fields(field, values)
            if new is not field:
                updates[name] = new
        return value.model_copy(update=updates) if updates else value
    items = [resolve_factor_fields(v, values) for v in value]
    if all(a is b for a, b in zip(items, value)):
        return value
    return type(value)(items) if isinstance(value, tuple) else items
