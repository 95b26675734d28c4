"""The one place psyop reaches into psignifit's private modules.

psyop's fit (:mod:`psyop.statistics.psignifit_grid`) runs psignifit's own pipeline step by step,
and some of those steps live in psignifit's private modules (``psignifit._parameter``,
``psignifit._posterior``, ``psignifit._priors``), which may move or change with any release.
:data:`PRIVATE_SYMBOLS` names every such symbol, the parameters psyop calls it with and what it is
for. :func:`private_symbol` imports one and checks it against its entry; a symbol that moved or
whose parameters changed raises :class:`PsignifitInternalsChanged` naming the symbol and the
installed psignifit version (tests/statistics/test_psignifit_private.py checks the whole table, so
an upgrade fails there, not deep in a fit).

``calls`` entries are called by psyop's fit; ``reference`` entries are psignifit functions psyop
re-implements (vectorised), which the tests hold psyop's versions to.
"""

from __future__ import annotations

import functools
import importlib
import inspect
from collections.abc import Callable
from dataclasses import dataclass
from importlib import metadata
from typing import Any, Literal

import numpy as np

from psyop.errors import UserError

#: The psignifit releases whose private modules :data:`PRIVATE_SYMBOLS` describes (pyproject.toml's pin).
SUPPORTED_PSIGNIFIT = ">=4.3,<4.4"


@dataclass(frozen=True)
class PrivateSymbol:
    """A private psignifit function psyop uses: where it lives, its parameter names in order, and why."""

    module: str
    name: str
    parameters: tuple[str, ...]
    role: Literal["calls", "reference"]
    use: str

    @property
    def qualified_name(self) -> str:
        return f"{self.module}.{self.name}"


PRIVATE_SYMBOLS: tuple[PrivateSymbol, ...] = (
    PrivateSymbol("psignifit._parameter", "parameter_bounds",
                  ("min_width", "experiment_type", "stimulus_range", "alpha", "nafc_choices"), "calls",
                  "the prior bounds of every parameter for the tested levels"),
    PrivateSymbol("psignifit._parameter", "masked_parameter_bounds", ("grid", "mesh_mask"), "calls",
                  "the bounds tightened on the sparse grid's posterior"),
    PrivateSymbol("psignifit._posterior", "integral_weights", ("grid",), "calls",
                  "the trapezoid weights that turn the posterior density into mass per grid point"),
    PrivateSymbol("psignifit._priors", "setup_priors",
                  ("custom_priors", "bounds", "stimulus_range", "width_min", "width_alpha", "beta_prior",
                   "threshold_prop_correct"), "calls",
                  "psignifit's default priors over the bounds"),
    PrivateSymbol("psignifit._parameter", "parameter_grid", ("bounds", "steps"), "reference",
                  "the grid psyop's _parameter_grid reproduces"),
    PrivateSymbol("psignifit._posterior", "log_posterior", ("data", "sigmoid", "priors", "grid"), "reference",
                  "the log posterior psyop's log_posterior_2afc reproduces, vectorised"),
)


class PsignifitInternalsChanged(UserError):
    """The installed psignifit lacks a private symbol psyop uses, or its parameters changed."""


def installed_psignifit_version() -> str:
    """The installed psignifit's version (its distribution metadata), or "not installed"."""
    try:
        return metadata.version("psignifit")
    except metadata.PackageNotFoundError:
        return "not installed"


def _changed(symbol: PrivateSymbol, what: str) -> PsignifitInternalsChanged:
    return PsignifitInternalsChanged(
        f"psignifit {installed_psignifit_version()}: {symbol.qualified_name} {what}; psyop uses it for "
        f"{symbol.use}. Install psignifit{SUPPORTED_PSIGNIFIT} (pip install 'psignifit{SUPPORTED_PSIGNIFIT}'), "
        "or port psyop.statistics.psignifit_private to this release", "psignifit")


def load_symbol(symbol: PrivateSymbol) -> Callable[..., Any]:
    """Import ``symbol`` and check that its parameter names are :attr:`PrivateSymbol.parameters`, in order.

    Raises :class:`PsignifitInternalsChanged` naming the symbol and the installed version otherwise."""
    try:
        module = importlib.import_module(symbol.module)
    except ImportError as err:
        raise _changed(symbol, f"cannot be imported ({symbol.module}: {err})") from err
    found = getattr(module, symbol.name, None)
    if not callable(found):
        raise _changed(symbol, "is missing" if found is None else "is no longer a function")
    try:
        parameters = tuple(inspect.signature(found).parameters)
    except (TypeError, ValueError) as err:
        raise _changed(symbol, f"has no readable signature ({err})") from err
    if parameters != symbol.parameters:
        raise _changed(symbol, f"takes ({', '.join(parameters)}) where psyop passes ({', '.join(symbol.parameters)})")
    return found


@functools.cache
def private_symbol(name: str) -> Callable[..., Any]:  # Any: psignifit ships no type information
    """The checked private psignifit function ``name`` of :data:`PRIVATE_SYMBOLS` (imported once)."""
    entry = next((s for s in PRIVATE_SYMBOLS if s.name == name), None)
    if entry is None:
        raise KeyError(f"{name!r} is not in PRIVATE_SYMBOLS; add it there with its parameters before using it")
    return load_symbol(entry)


def parameter_bounds(min_width: float, experiment_type: str, stimulus_range: tuple[float, float], alpha: float,
                     nafc_choices: int | None) -> dict[str, tuple[float, float]]:
    """``psignifit._parameter.parameter_bounds``: each parameter's prior bounds for these levels."""
    return dict(private_symbol("parameter_bounds")(
        min_width=min_width, experiment_type=experiment_type, stimulus_range=stimulus_range, alpha=alpha,
        nafc_choices=nafc_choices))


def masked_parameter_bounds(grid: dict[str, np.ndarray], mesh_mask: np.ndarray) -> dict[str, tuple[float, float]]:
    """``psignifit._parameter.masked_parameter_bounds``: the bounds of the grid points where ``mesh_mask`` holds."""
    return dict(private_symbol("masked_parameter_bounds")(grid, mesh_mask))


def integral_weights(grid: list[np.ndarray]) -> np.ndarray:
    """``psignifit._posterior.integral_weights``: trapezoid weights over the axes ``grid``, as a mesh."""
    return np.asarray(private_symbol("integral_weights")(grid))


def setup_priors(bounds: dict[str, tuple[float, float]], stimulus_range: tuple[float, float], width_min: float,
                 width_alpha: float, beta_prior: float, threshold_prop_correct: float
                 ) -> dict[str, Callable[[np.ndarray], np.ndarray]]:
    """``psignifit._priors.setup_priors`` without custom priors: psignifit's default prior of each parameter."""
    return dict(private_symbol("setup_priors")(
        custom_priors=None, bounds=bounds, stimulus_range=stimulus_range, width_min=width_min,
        width_alpha=width_alpha, beta_prior=beta_prior, threshold_prop_correct=threshold_prop_correct))
