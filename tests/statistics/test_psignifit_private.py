"""psyop's boundary to psignifit's private modules (psyop.statistics.psignifit_private).

Every private symbol psyop uses is in PRIVATE_SYMBOLS; this test imports each from the installed psignifit and
checks its parameters, so a psignifit release that moves or changes one fails here, with a message naming the
symbol and the installed version, rather than deep in a fit. No other module of psyop, its tests or benchmarks
imports a private psignifit module.
"""

from __future__ import annotations

import ast
import importlib
import tomllib
from pathlib import Path

import numpy as np
import pytest

from psyop.statistics import psignifit_private as private
from psyop.statistics.psychometric import FitOptions, fit_psychometric
from psyop.statistics.psignifit_private import (
    PRIVATE_SYMBOLS, SUPPORTED_PSIGNIFIT, PrivateSymbol, PsignifitInternalsChanged, installed_psignifit_version,
    load_symbol,
)

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("symbol", PRIVATE_SYMBOLS, ids=[s.qualified_name for s in PRIVATE_SYMBOLS])
def test_every_private_symbol_is_where_psyop_expects_it_with_its_parameters(symbol: PrivateSymbol):
    found = load_symbol(symbol)  # raises PsignifitInternalsChanged naming the symbol and the version
    assert found.__module__ == symbol.module and found.__name__ == symbol.name
    assert private.private_symbol(symbol.name) is found


@pytest.mark.parametrize("entry, says", [
    (PrivateSymbol("psignifit._parameter", "parameter_bounds", ("min_width", "experiment_type"), "calls", "bounds"),
     "takes (min_width, experiment_type, stimulus_range, alpha, nafc_choices) where psyop passes "
     "(min_width, experiment_type)"),
    (PrivateSymbol("psignifit._parameter", "no_such_function", ("grid",), "calls", "a test"), "is missing"),
    (PrivateSymbol("psignifit._no_such_module", "integral_weights", ("grid",), "calls", "a test"),
     "cannot be imported"),
    (PrivateSymbol("psignifit._parameter", "__name__", (), "calls", "a test"), "is no longer a function"),
])
def test_a_moved_or_changed_symbol_fails_naming_it_and_the_installed_version(entry: PrivateSymbol, says: str):
    with pytest.raises(PsignifitInternalsChanged) as caught:
        load_symbol(entry)
    message = str(caught.value)
    assert entry.qualified_name in message and says in message
    assert f"psignifit {installed_psignifit_version()}:" in message
    assert f"psignifit{SUPPORTED_PSIGNIFIT}" in message  # the fix
    assert "\n" not in message


@pytest.mark.parametrize("change", ["removed", "new parameter"])
def test_a_fit_on_a_psignifit_whose_internals_changed_stops_with_that_message(monkeypatch, change: str):
    """The installed psignifit's own module altered the way a release could: the fit stops at its first use of
    the symbol with the boundary's message (a UserError: one line, exit 2), not with a TypeError inside psignifit."""
    module = importlib.import_module("psignifit._priors")
    if change == "removed":
        monkeypatch.delattr(module, "setup_priors")
    else:
        monkeypatch.setattr(module, "setup_priors", lambda custom_priors, bounds, stimulus_range, width_min,
                            width_alpha, beta_prior, threshold_prop_correct, sigmoid: None)
    private.private_symbol.cache_clear()
    try:
        with pytest.raises(PsignifitInternalsChanged, match=r"psignifit\._priors\.setup_priors (is missing|takes)"):
            # levels no other test fits, so psignifit's bounds and priors are not yet cached for them
            fit_psychometric(np.c_[[0.13, 0.37, 0.91], [9, 12, 15], [15, 15, 15]], FitOptions(n_bootstrap=0))
    finally:
        private.private_symbol.cache_clear()  # the real symbol is loaded again once the patch is undone


def test_a_symbol_outside_the_table_is_refused():
    with pytest.raises(KeyError, match="not in PRIVATE_SYMBOLS"):
        private.private_symbol("log_likelihood")


def test_the_supported_range_is_the_dependency_pin():
    dependencies = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["dependencies"]
    assert f"psignifit{SUPPORTED_PSIGNIFIT}" in [d.replace(" ", "") for d in dependencies]


def _private_imports(path: Path) -> list[str]:
    """``psignifit._*`` modules imported by ``path`` (import statements anywhere, and ``psignifit._x`` attributes)."""
    text = path.read_text()
    if "psignifit" not in text:
        return []
    found = []
    for node in ast.walk(ast.parse(text, str(path))):
        if isinstance(node, ast.ImportFrom) and node.module:
            names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "psignifit":
            names = [f"psignifit.{node.attr}"]
        else:
            continue
        found += [n for n in names if n.startswith("psignifit.") and n.split(".")[1].startswith("_")]
    return found


def test_only_the_boundary_module_imports_psignifit_internals():
    boundary = REPO / "psyop" / "statistics" / "psignifit_private.py"
    files = [p for folder in ("psyop", "tests", "benchmarks", "analysis") for p in (REPO / folder).rglob("*.py")]
    offenders = {str(p.relative_to(REPO)): _private_imports(p) for p in files if p != boundary}
    assert {p: names for p, names in offenders.items() if names} == {}
    assert len(files) > 100  # the scan saw the repository
