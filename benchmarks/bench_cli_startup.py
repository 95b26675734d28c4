"""Start-up of the `psyop` command: lazy sub-command imports against the eager imports of before.

Before issue 13 every invocation imported every sub-command module and with them pandas,
numpy, pyarrow and pydantic (psyop.schedule, psyop.protocol). "eager (before)" reproduces that
import set in the same run, so the ratio is side by side on one machine.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
EAGER = ("import psyop.protocol, psyop.schedule.compile, psyop.schedule.io, psyop.schedule.summary, numpy\n")


def _wall_s(code: str, argv: list[str], n: int) -> np.ndarray:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    out = np.empty(n)
    for k in range(n):
        start = time.perf_counter()
        subprocess.run([sys.executable, "-c", code, *argv], cwd=REPO, env=env, capture_output=True, check=False)
        out[k] = time.perf_counter() - start
    return out


def run(out_dir: Path, quick: bool) -> str:
    n = 3 if quick else 10
    main = "import sys\nfrom psyop.cli import main\ntry:\n    main(sys.argv[1:])\nexcept SystemExit:\n    pass\n"
    cases = {
        "psyop --help": ["--help"],
        "psyop validate protocols/detection.yaml": ["validate", "protocols/detection.yaml"],
    }
    bare = np.median(_wall_s("pass", [], n))
    lines = [
        "## CLI start-up: lazy sub-command imports",
        "",
        f"Median wall time of {n} fresh processes each (the Python interpreter alone: {bare * 1e3:.0f} ms).",
        "",
        "| command | lazy (now) ms | eager (before) ms | now / before |",
        "|---|---|---|---|",
    ]
    for label, argv in cases.items():
        lazy = np.median(_wall_s(main, argv, n))
        eager = np.median(_wall_s(EAGER + main, argv, n))
        lines.append(f"| `{label}` | {lazy * 1e3:.0f} | {eager * 1e3:.0f} | {lazy / eager:.2f} |")
    return "\n".join(lines)
