"""Every Makefile variable that holds a path is quoted where a recipe uses it, so a path with a space
(`make figures DATA='/path/with a space/data'`, a python or make under such a path) is one word to the
shell. Checked on the recipe text and, for the interpreter, with make's dry run, which runs the
`psyop studies` step for real (no install: the venv stamps are given as fresh files)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: the variables that name a path (a file, a folder, an interpreter or make itself), and make's $@ / $<
PATH_VARIABLES = ("PY", "PYTHON", "VENV", "DATA", "RESULTS", "FIGDIR", "POWER", "ANALYSE", "MAKE", "STAMP")
USE = re.compile(r"\$\((" + "|".join(PATH_VARIABLES) + r")\)|\$[@<]")


def _unquoted(line: str) -> list[str]:
    """The path uses on a recipe line outside double quotes (single-quoted sed/grep text aside)."""
    found = []
    for match in USE.finditer(line):
        before = line[: match.start()]
        if before.count('"') % 2 == 0 and before.count("'") % 2 == 0:
            found.append(match.group(0))
    return found


def _recipes(text: str) -> list[tuple[int, str]]:
    return [(i, line) for i, line in enumerate(text.splitlines(), 1) if line.startswith("\t")]


def test_every_path_variable_is_quoted_in_the_recipes() -> None:
    from psyop.cli.studies import make_rules  # the per-study rules make includes

    found = []
    for name in ("Makefile", "figures.mk"):
        for i, line in _recipes((REPO / name).read_text()):
            found += [f"{name}:{i}: {use} in {line.strip()}" for use in _unquoted(line)]
    assert not found, "unquoted paths in recipes:\n" + "\n".join(found)
    assert callable(make_rules)


def test_generated_study_rules_quote_their_paths(tmp_path: Path) -> None:
    data = tmp_path / "with a space" / "data"
    session = data / "detection" / "sub-S01" / "ses-1"
    session.mkdir(parents=True)
    (session / "trials.parquet").write_bytes(b"")
    import hashlib
    import json

    sha = hashlib.sha256((REPO / "protocols" / "detection.yaml").read_bytes()).hexdigest()
    (session / "session.json").write_text(json.dumps({"response_kind": "2afc_interval", "protocol_sha256": sha}))
    from psyop.cli.studies import make_rules

    text, _ = make_rules(data, REPO / "protocols")
    found = [f"{i}: {use} in {line.strip()}" for i, line in _recipes(text) for use in _unquoted(line)]
    assert "detection_fits.csv" in text and not found, "\n".join(found)


def test_an_interpreter_under_a_path_with_a_space_runs(tmp_path: Path) -> None:
    """figures-build runs `$(PY) -m psyop studies` even in a dry run: with PY under a folder with a space it
    was `.../with: No such file or directory` (the path cut at its space)."""
    bin_dir = tmp_path / "with a space" / "bin"
    bin_dir.mkdir(parents=True)
    python = bin_dir / "python"  # a wrapper, not a link: the venv's python finds its packages from its own path
    python.write_text(f'#!/bin/sh\nexec "{sys.executable}" "$@"\n')
    python.chmod(0o755)
    data = tmp_path / "data dir"
    data.mkdir()
    stamp, sysdeps = tmp_path / "stamp", tmp_path / "sysdeps-stamp"  # fresh: make never installs anything
    stamp.write_text("")
    sysdeps.write_text("")
    done = subprocess.run(
        ["make", "--no-print-directory", "-n", "-C", str(REPO), "figures-build", f"PY={bin_dir / 'python'}",
         f"DATA={data}", f"RESULTS={tmp_path / 'results'}", f"FIGDIR={tmp_path / 'figures'}",
         f"STAMP={stamp}", f"SYSDEPS_STAMP={sysdeps}"],
        capture_output=True, text=True, timeout=300, env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "results" / ".studies.mk").is_file()
    assert "pip install" not in done.stdout
