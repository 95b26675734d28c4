"""The suite holds on a loaded machine: no test asserts a wall-clock duration or sleeps a
fixed time to wait for something, and hypothesis is derandomised in every run.

Durations belong in benchmarks/ (`make bench`); a test waits for an event by polling with a
generous deadline (tests/session/session_helpers.wait_until).
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parent
WALL_CLOCKS = {"perf_counter", "perf_counter_ns", "time", "process_time"}
NOT_A_WAIT = "# not a wait"


def _sources() -> list[Path]:
    return sorted(p for p in TESTS.rglob("*.py") if p.name != Path(__file__).name)


def _inside_while(node: ast.AST, parents: dict[ast.AST, ast.AST]) -> bool:
    while node in parents:
        node = parents[node]
        if isinstance(node, ast.While):
            return True
    return False


def test_no_test_reads_a_duration_clock_or_sleeps_to_wait() -> None:
    problems = []
    for path in _sources():
        text = path.read_text()
        lines = text.splitlines()
        try:
            tree = ast.parse(text)
        except SyntaxError as exc:
            problems.append(f"{path.relative_to(TESTS.parent)}:{exc.lineno}: does not parse ({exc.msg})")
            continue
        parents = {child: parent for parent in ast.walk(tree) for child in ast.iter_child_nodes(parent)}
        for node in ast.walk(tree):
            if not isinstance(node, ast.Call) or not isinstance(node.func, ast.Attribute):
                continue
            owner = node.func.value
            if not (isinstance(owner, ast.Name) and owner.id == "time"):
                continue
            where = f"{path.relative_to(TESTS.parent)}:{node.lineno}"
            if node.func.attr in WALL_CLOCKS:
                problems.append(f"{where}: time.{node.func.attr}() measures a duration (move it to benchmarks/)")
            elif node.func.attr == "sleep" and not _inside_while(node, parents) and NOT_A_WAIT not in lines[node.lineno - 1]:
                problems.append(f"{where}: a fixed sleep outside a polling loop (use session_helpers.wait_until)")
    assert not problems, "\n".join(problems)


def test_hypothesis_is_derandomised_without_any_environment_variable() -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("CI", "PSYOP_HYPOTHESIS", "HYPOTHESIS_PROFILE")}
    code = ("import sys; sys.path.insert(0, sys.argv[1]); import conftest; from hypothesis import settings; "
            "print(settings.default.derandomize, settings.default.deadline)")
    out = subprocess.run([sys.executable, "-c", code, str(TESTS)], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["True", "None"]
