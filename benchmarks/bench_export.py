"""The five shipped studies, simulated, exported as BIDS and checked by the official validator;
and the cost of verifying finalised files (SHA-256) beside the cost of reading them.

Full run: the paper's sample sizes (63 sessions); ``--quick``: one participant per study. The
validator is bids-validator-deno (the test extra), run with ``--max-rows -1`` (every row). The
verification cost is the median over repeats of :func:`psyop.finalised.verify_session` on every
session against ``pd.read_parquet`` of the same sessions' trials.parquet, interleaved in one
process: the claim is their ratio.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import pandas as pd

from benchmarks.timing import median_s
from psyop.export.bids import export_bids
from psyop.finalised import verify_session
from psyop.run.simulate import simulate_dataset

REPO = Path(__file__).resolve().parents[1]


def _validate(root: Path) -> tuple[int | None, Counter]:
    exe = Path(sys.executable).with_name("bids-validator-deno")
    if not exe.exists():
        return None, Counter()
    result = subprocess.run([str(exe), str(root), "--format", "json", "--max-rows", "-1"], capture_output=True,
                            text=True, timeout=1800)
    try:
        issues = json.loads(result.stdout)["issues"]["issues"]
    except (ValueError, KeyError):
        return result.returncode, Counter({"unparsed output": 1})
    return result.returncode, Counter(i["severity"] for i in issues)


def run(out: Path, quick: bool) -> str:
    with tempfile.TemporaryDirectory() as tmp:
        data, bids = Path(tmp) / "data", Path(tmp) / "bids"
        protocols = sorted((REPO / "protocols").glob("*.yaml"))
        sizes = {p.stem: 1 for p in protocols} if quick else None
        start = time.perf_counter()
        simulate_dataset(protocols, data, jobs=1 if quick else 2, participants=sizes)
        simulate_s = time.perf_counter() - start
        start = time.perf_counter()
        result = export_bids(data, bids)
        export_s = time.perf_counter() - start
        start = time.perf_counter()
        code, issues = _validate(bids)
        validate_s = time.perf_counter() - start
        physio = sorted(bids.glob("sub-*/ses-*/beh/*_physio.tsv.gz"))
        sessions = [Path(p).parent for p in sorted(data.glob("*/sub-*/ses-*/trials.parquet"))]
        repeats = 3 if quick else 7
        verify = median_s(lambda: [verify_session(s) for s in sessions], repeats)
        read = median_s(lambda: [pd.read_parquet(s / "trials.parquet") for s in sessions], repeats)
        with_physio = {p.name.split("_run-")[0] for p in physio}  # sub-<ID>_ses-<N>_task-<study>
    validator = ("not installed (pip install bids-validator-deno)" if code is None
                 else f"exit {code}, {issues.get('error', 0)} errors, {issues.get('warning', 0)} warnings")
    return "\n".join([
        "## BIDS export of the simulated studies (bench_export)",
        "",
        f"{len(result.sessions)} simulated sessions ({'one participant per study' if quick else 'paper sizes'}), "
        f"simulated in {simulate_s:.1f} s, exported in {export_s:.1f} s; bids-validator-deno --max-rows -1: "
        f"{validator} in {validate_s:.1f} s.",
        f"Eye-tracking physio files: {len(physio)} (sessions with at least one: {len(with_physio)} of "
        f"{len(result.sessions)}); gaze source: {', '.join(sorted({s.gaze_source for s in result.sessions}))}.",
        "",
        "| step, all sessions | median wall |",
        "|---|---|",
        f"| verify_session (SHA-256 of trials.parquet + frames.parquet) | {verify * 1e3:.1f} ms |",
        f"| pd.read_parquet(trials.parquet) | {read * 1e3:.1f} ms |",
        f"| ratio verify / read | {verify / read:.2f} |",
    ]) + "\n"
