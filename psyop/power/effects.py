"""``--effect KEY=VALUE``: set a parameter of the protocol's simulated observer for a power run
(e.g. ``threshold_slope=0.05``). The changed observer is validated like the protocol itself, so
an unknown key or a bad value is a user error, not an ignored setting."""

from __future__ import annotations

import yaml
from pydantic import ValidationError

from psyop.errors import UserError
from psyop.protocol.model import Protocol


def parse_effects(specs: list[str]) -> tuple[tuple[str, object], ...]:
    out = []
    for spec in specs:
        key, sep, value = spec.partition("=")
        key = key.strip()
        if key.startswith("observer."):
            key = key[len("observer."):]
        if not sep or not key:
            raise UserError(f"--effect {spec!r}: write KEY=VALUE, e.g. threshold_slope=0.05", "--effect")
        try:
            parsed = yaml.safe_load(value)
        except (yaml.YAMLError, ValueError, TypeError, AttributeError, KeyError) as exc:
            # an explicit tag with a bad value (!!timestamp foo, !!int x) fails inside yaml's constructors with
            # plain Python errors, not YAMLError
            detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise UserError(f"--effect {spec!r}: the value is not valid YAML ({detail}); write a number, "
                            "e.g. threshold_slope=0.05", "--effect") from None
        out.append((key, parsed))
    return tuple(out)


def apply_effects(protocol: Protocol, effects: tuple[tuple[str, object], ...]) -> Protocol:
    """A copy of ``protocol`` whose observer has ``effects`` set (validated)."""
    if not effects:
        return protocol
    if protocol.observer is None:
        raise UserError("--effect needs an observer: section in the protocol", "--effect")
    observer_type = type(protocol.observer)
    data = protocol.observer.model_dump()
    for key, value in effects:
        if key not in observer_type.model_fields or key == "kind":
            known = ", ".join(k for k in observer_type.model_fields if k != "kind")
            raise UserError(f"--effect {key}: not a parameter of the {data['kind']} observer (known: {known})",
                            "--effect")
        data[key] = value
    try:
        observer = observer_type.model_validate(data)
    except ValidationError as exc:
        raise UserError(f"--effect: the changed observer is invalid: {exc}", "--effect") from None
    return protocol.model_copy(update={"observer": observer})
