"""The README's commands run as written, headless (issue 13: every `psyop` line failed for a
newcomer, the demo wrote into data/, the replay example pointed at no session).

Every ```sh block is run line by line in bash from a scratch copy of the repository root
(protocols/ linked, data/ holding what `make figures` simulates for the replay source), with
`psyop` meaning this checkout's CLI. Blocks after ``<!-- readme-test: skip (why) -->`` need
hardware; `make` lines are the two set-up commands (run by CI itself) and are not rerun here.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"


def readme_blocks() -> list[tuple[str, bool]]:
    """(block text, skipped) for every ```sh block of the README."""
    text = README.read_text()
    blocks = []
    for match in re.finditer(r"(<!-- readme-test: skip[^>]*-->\s*)?```sh\n(.*?)```", text, re.S):
        blocks.append((match.group(2), match.group(1) is not None))
    return blocks


def commands(block: str) -> list[str]:
    joined = re.sub(r"\\\n\s*", " ", block)
    return [line.strip() for line in joined.splitlines() if line.strip() and not line.lstrip().startswith("#")]


def test_readme_says_how_to_get_psyop_on_path() -> None:
    runnable = [c for b, skip in readme_blocks() if not skip for c in commands(b)]
    first_psyop = next(i for i, c in enumerate(runnable) if c.startswith("psyop "))
    assert any(c.startswith("source .venv/bin/activate") for c in runnable[:first_psyop])
    assert (REPO / "pyproject.toml").read_text().count('psyop = "psyop.cli:main"') == 1  # what puts it in .venv/bin


def test_examples_write_only_to_the_scratch_directory() -> None:
    for block, skip in readme_blocks():
        for command in commands(block):
            if command.startswith("psyop run") and not skip:
                assert "--data demo" in command, command
            assert not re.search(r"--out (?!demo/)", command), command
            assert not re.search(r"> (?!demo/)\S", command), command


@pytest.mark.slow
def test_readme_examples_run_headless_as_written(tmp_path: Path) -> None:
    root = tmp_path / "clone"
    root.mkdir()
    (root / "protocols").symlink_to(REPO / "protocols")
    (root / "assets").symlink_to(REPO / "assets")  # the models protocols/ name (../assets/...)
    (tmp_path / "assets").symlink_to(REPO / "assets")  # ... from protocols_egocentric below
    env = dict(os.environ, PYTHONPATH=str(REPO), MPLBACKEND="Agg")
    env.pop("DISPLAY", None)  # headless means no X display
    # what `make figures` creates for the replay example: participant S01 of the simulated dataset
    only_egocentric = tmp_path / "protocols_egocentric"
    only_egocentric.mkdir()
    (only_egocentric / "egocentric.yaml").symlink_to(REPO / "protocols" / "egocentric.yaml")
    subprocess.run([sys.executable, "-m", "psyop", "simulate", "--data", "data", "--protocols", str(only_egocentric),
                    "--participants", "1", "--jobs", "1"], cwd=root, env=env, check=True, capture_output=True)
    ran = []
    for block, skip in readme_blocks():
        if skip:
            continue
        for command in commands(block):
            if command.startswith(("make ", "source ")):
                continue  # the set-up commands; psyop is this checkout's CLI here
            script = f'psyop() {{ "{sys.executable}" -m psyop "$@"; }}\nset -euo pipefail\n{command}\n'
            result = subprocess.run(["bash", "-c", script], cwd=root, env=env, capture_output=True, text=True, timeout=600)
            assert result.returncode == 0, f"README command failed: {command}\n{result.stderr[-3000:]}"
            ran.append(command)
    assert sum(c.startswith("psyop ") for c in ran) >= 10
    for made in ("demo/schedule.parquet", "demo/protocol.schema.json", "demo/frame.png",
                 "demo/detection/sub-sim01/ses-1/trials.parquet", "demo/egocentric/sub-replay01/ses-1/trials.parquet"):
        assert (root / made).is_file(), made
    # the paper dataset is untouched: only the simulated source session is in data/
    assert sorted(p.relative_to(root / "data").as_posix() for p in (root / "data").glob("*/sub-*")) == ["egocentric/sub-S01"]
