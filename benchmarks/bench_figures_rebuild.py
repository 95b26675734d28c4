"""`make figures` run time: a full rebuild against an incremental one after one new session.

Simulates the paper-sized dataset into a scratch data root, times a full `make figures-build`
into scratch figure/result folders, adds one detection session with `psyop run`, and times the
rebuild that follows (make should redo only the detection fits, its figures and the summary).
The claim is the ratio; absolute times are this machine's CPU.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _make(target: str, scratch: Path, jobs: int) -> tuple[float, list[str]]:
    cmd = [
        "make", "--no-print-directory", "-C", str(REPO), target,
        f"DATA={scratch / 'data'}", f"RESULTS={scratch / 'results'}", f"FIGDIR={scratch / 'figures'}", f"JOBS={jobs}",
    ]
    start = time.perf_counter()
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    return time.perf_counter() - start, [line for line in out.splitlines() if line.startswith("[psyop]")]


def run(out_dir: Path, quick: bool) -> str:
    jobs = os.cpu_count() or 2
    with tempfile.TemporaryDirectory(prefix="psyop-bench-figures-") as tmp:
        scratch = Path(tmp)
        participants = ["--participants", "2"] if quick else []
        start = time.perf_counter()
        subprocess.run(
            [sys.executable, "-m", "psyop", "simulate", "--data", str(scratch / "data"),
             "--protocols", str(REPO / "protocols"), "--jobs", str(jobs), *participants],
            check=True, capture_output=True, text=True,
        )
        simulate_s = time.perf_counter() - start
        full_s, full_steps = _make("figures-build", scratch, jobs)
        subprocess.run(
            [sys.executable, "-m", "psyop", "run", str(REPO / "protocols" / "detection.yaml"),
             "--participant", "NEW01", "--data", str(scratch / "data"), "--no-progress", "--render", "cameras"],
            check=True, capture_output=True, text=True,
        )
        incremental_s, incremental_steps = _make("figures-build", scratch, jobs)
        noop_s, noop_steps = _make("figures-build", scratch, jobs)
    size = "2 participants per study (quick)" if quick else "the paper's sizes (6/6/19/13/19 participants)"
    rebuilt = ", ".join(s.removeprefix("[psyop] ").rsplit("/", 1)[-1] for s in incremental_steps)
    return "\n".join([
        "## make figures: full vs incremental rebuild",
        "",
        f"Simulated dataset at {size}, {jobs} jobs.",
        "",
        "| step | wall s | steps run |",
        "|---|---|---|",
        f"| simulate all five studies | {simulate_s:.1f} | - |",
        f"| full rebuild (figures-build) | {full_s:.1f} | {len(full_steps)} |",
        f"| rebuild after one new detection session | {incremental_s:.1f} | {len(incremental_steps)} |",
        f"| rebuild with nothing changed | {noop_s:.2f} | {len(noop_steps)} |",
        "",
        f"Incremental / full = **{incremental_s / full_s:.2f}**. Rebuilt after the new session: {rebuilt}.",
    ])
