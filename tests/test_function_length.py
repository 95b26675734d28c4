"""No function in psyop/ is longer than 60 lines, from its ``def`` to its last line, docstring included
(issue 28: small functions with one job; benchmarks/ and tests/ are not held to it)."""

from __future__ import annotations

import ast
from pathlib import Path

PSYOP = Path(__file__).resolve().parents[1] / "psyop"
MAX_LINES = 60


def test_no_function_in_psyop_is_over_60_lines() -> None:
    long = []
    for path in sorted(PSYOP.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = (node.end_lineno or node.lineno) - node.lineno + 1
                if lines > MAX_LINES:
                    long.append(f"{path.relative_to(PSYOP.parent)}:{node.lineno} {node.name}: {lines} lines")
    assert not long, "split these functions (at most 60 lines each):\n" + "\n".join(long)
