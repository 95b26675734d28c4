"""The response kinds: one module per kind in this package, each defining ``KIND``, its
:class:`~psyop.protocol.kinds.base.ResponseKindSpec`. Every module here that defines ``KIND`` is a kind;
nothing else registers it (docs/architecture.md, "How to add a response kind").

:func:`kind_named` finds a kind by its one spelling (or a spelling session.json had before it had one).
"""

from __future__ import annotations

import importlib
import pkgutil

from psyop.protocol.kinds.base import KindResponse, ObserverBase, ResponseKindSpec


def _discover() -> dict[str, ResponseKindSpec]:
    found: dict[str, ResponseKindSpec] = {}
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{__name__}.{info.name}")
        kind = getattr(module, "KIND", None)
        if kind is None:
            continue
        if not isinstance(kind, ResponseKindSpec):
            raise TypeError(f"{module.__name__}.KIND is not a ResponseKindSpec")
        if kind.name in found:
            raise TypeError(f"two response kinds are named {kind.name!r}")
        found[kind.name] = kind
    return found


#: every response kind by its name, in name order
KINDS: dict[str, ResponseKindSpec] = _discover()
_SPELLINGS: dict[str, ResponseKindSpec] = {former: kind for kind in KINDS.values() for former in kind.former_names} | KINDS


def kind_named(name: str) -> ResponseKindSpec:
    """The kind called ``name`` (or a former session.json spelling of it); KeyError naming the known kinds."""
    try:
        return _SPELLINGS[name]
    except KeyError:
        raise KeyError(f"{name!r} is not a response kind (kinds: {', '.join(KINDS)})") from None


def kind_of(response: KindResponse) -> ResponseKindSpec:
    """The kind of a protocol's ``response:`` section."""
    return KINDS[response.kind]


def response_models() -> tuple[type[KindResponse], ...]:
    """Every kind's ``response:`` model."""
    return tuple(kind.model for kind in KINDS.values())


def observer_models() -> tuple[type[ObserverBase], ...]:
    """Every kind's simulated-observer models."""
    return tuple(model for kind in KINDS.values() for model in kind.observer_models)


__all__ = ["KINDS", "KindResponse", "ObserverBase", "ResponseKindSpec", "kind_named", "kind_of", "observer_models",
           "response_models"]
