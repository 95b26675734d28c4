"""The repository names only paths relative to itself (../shared) or given by the environment:
`.ci/run` looked for the OpenXR test runtime's build script at an absolute /work/shared/openxr too."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: an absolute path into this workplace's own folders (the checkout's parent, a home folder)
ABSOLUTE = re.compile(r"(?<![\w.~])/(work|home|root)/")


def test_no_absolute_workplace_paths_in_code_or_ci() -> None:
    files = subprocess.run(["git", "ls-files", ".ci", "Makefile", "figures.mk", "pyproject.toml", "psyop",
                            "analysis", "benchmarks", "protocols", "assets"],
                           cwd=REPO, capture_output=True, text=True, check=True).stdout.split()
    assert ".ci/run" in files
    found = []
    for name in files:
        path = REPO / name
        try:
            text = path.read_text(encoding="utf-8")
        except (UnicodeDecodeError, OSError):
            continue  # binary assets
        found += [f"{name}:{i}: {line.strip()}" for i, line in enumerate(text.splitlines(), 1)
                  if ABSOLUTE.search(line)]
    assert not found, "absolute paths outside the repository:\n" + "\n".join(found)
