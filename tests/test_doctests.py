"""The docstring examples (``>>>``) in psyop/ run here, so ``make test`` keeps them true (issue 28).

Modules are found by their text, so a module that gains an example, or moves (e.g. into psyop/devices/),
is covered without listing it here."""

from __future__ import annotations

import doctest
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _modules_with_examples() -> list[str]:
    names = []
    for path in sorted((ROOT / "psyop").rglob("*.py")):
        if ">>>" not in path.read_text(encoding="utf-8"):
            continue
        parts = path.relative_to(ROOT).with_suffix("").parts
        names.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return names


MODULES = _modules_with_examples()


def test_examples_are_found() -> None:
    """A broken discovery (wrong root, renamed package) must fail, not pass with nothing collected."""
    assert len(MODULES) >= 30, MODULES


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_run(name: str) -> None:
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE, report=False)
    assert result.attempted > 0, f"{name} holds '>>>' but doctest found no example in it"
    assert result.failed == 0, f"{result.failed} of {result.attempted} docstring examples in {name} fail (run python -m doctest -v on it)"
