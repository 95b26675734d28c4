"""The stream rebuild of every simulated session of the paper-sized data (what a cold `make figures-build` does
per session before measuring it: verify, read, rebuild the requested stream from its seed, check it against
every recorded sample; :func:`psyop.quality.session.session_gaze`) on the code at :data:`BEFORE_REV` (the
rebuild asked of the simulated tracker phase by phase) and on this tree (each run's ticks at once,
:meth:`psyop.session.gaze.simulated.SimulatedTracker.samples_under`), side by side in one run.

Each tree runs in a process of its own (``PYTHONPATH`` puts its psyop first; the same interpreter and data),
its imports and a warm-up session outside the timing, then every session once; the trees alternate, twice
each, and the table gives each tree's CPU and wall seconds (the smaller of its two runs) and the ratio. Every
rebuilt stream of the two trees must be equal, every column bit for bit (the benchmark fails otherwise).
The data: ``PSYOP_BENCH_FIGURES_DATA`` when set (as :mod:`benchmarks.bench_figures_vs_c57032f`: simulated
there when it holds no session), else a scratch folder simulated here (``--quick``: 3 participants per study).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmarks.bench_figures_vs_c57032f import DATA_ENV, _copy_tree, _env, _tree

#: the code before the whole-run rebuild
BEFORE_REV = "a9b7079"

#: run in each tree's process: time session_gaze over every session, write each rebuilt stream
_TIMER = """
import json, sys, time
from pathlib import Path
import pandas as pd
from psyop.quality.session import session_gaze
data, out = Path(sys.argv[1]), Path(sys.argv[2])
sessions = sorted(p.parent for p in data.glob("*/sub-*/ses-*/trials.parquet"))
session_gaze(sessions[0])  # imports and first-use costs outside the timing
plans, cpu, wall, streams = {}, time.process_time(), time.perf_counter(), {}
for d in sessions:
    streams[d] = session_gaze(d, plans)
cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
if len(sys.argv) > 3:
    out.mkdir(parents=True, exist_ok=True)
    for i, (d, s) in enumerate(streams.items()):
        s.gaze.reset_index(drop=True).to_parquet(out / f"{i:03d}.parquet")
print(json.dumps({"cpu_s": cpu, "wall_s": wall, "sessions": len(sessions),
                  "samples": int(sum(len(s.gaze) for s in streams.values())),
                  "streams": sorted({s.stream for s in streams.values()})}))
"""


def timed(tree: Path, timer: str, data: Path, out: Path, keep: bool) -> dict:
    """Run ``timer`` (a script: argv data, out, and "keep" to write its outputs to out) in ``tree``'s process;
    the JSON its last line prints."""
    done = subprocess.run([sys.executable, "-c", timer, str(data), str(out), *(["keep"] if keep else [])],
                          env=_env(tree), cwd=tree, capture_output=True, text=True)
    if done.returncode:
        raise RuntimeError(f"{tree.name}: the timed script exited {done.returncode}: {done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def alternate(rev: str, scratch: Path, quick: bool, reps: int, timer: str) -> tuple[dict[str, list[dict]], float] | None:
    """``timer`` run on the tree of ``rev`` ("before") and on a copy of this one ("now"), alternating, ``reps``
    times each, over the simulated data (:func:`_data`); the first run of each writes its outputs to
    ``scratch``/before and ``scratch``/now. The runs and the load average before them; None when this clone does
    not hold ``rev``."""
    before = _tree(rev, scratch / "before-tree")
    if before is None:
        return None
    now = _copy_tree(scratch / "now-tree")
    data = _data(scratch, now, quick)
    load = os.getloadavg()[0]
    runs: dict[str, list[dict]] = {"before": [], "now": []}
    for rep in range(reps):
        for label, tree in (("before", before), ("now", now)):
            runs[label].append(timed(tree, timer, data, scratch / label, keep=rep == 0))
    return runs, load


def best_table(rev: str, runs: dict[str, list[dict]]) -> list[str]:
    """The smaller CPU and wall seconds of each tree's runs, and their ratio, as a table."""
    best = {k: (min(r["cpu_s"] for r in v), min(r["wall_s"] for r in v)) for k, v in runs.items()}
    return ["| code | CPU s | wall s |", "|---|---|---|",
            f"| {rev} | {best['before'][0]:.2f} | {best['before'][1]:.2f} |",
            f"| this tree | {best['now'][0]:.2f} | {best['now'][1]:.2f} |",
            f"| {rev} / this | {best['before'][0] / best['now'][0]:.2f} | {best['before'][1] / best['now'][1]:.2f} |"]


def _equal_streams(a: Path, b: Path) -> list[str]:
    """The rebuilt streams written by the two trees that are not equal, column by column, bit for bit."""
    import numpy as np
    import pandas as pd

    names = sorted(p.name for p in a.glob("*.parquet"))
    if names != sorted(p.name for p in b.glob("*.parquet")):
        return ["the two trees rebuilt different session lists"]
    bad = []
    for name in names:
        x, y = pd.read_parquet(a / name), pd.read_parquet(b / name)
        same = list(x.columns) == list(y.columns) and len(x) == len(y) and all(
            np.array_equal(x[c].to_numpy(), y[c].to_numpy(), equal_nan=x[c].dtype.kind == "f") for c in x.columns)
        if not same:
            bad.append(name)
    return bad


def _data(scratch: Path, now: Path, quick: bool) -> Path:
    kept = os.environ.get(DATA_ENV)
    data = Path(kept).resolve() if kept else scratch / "data"
    if not any(data.glob("*/sub-*/ses-*/trials.parquet")):
        subprocess.run([sys.executable, "-m", "psyop", "simulate", "--data", str(data), "--protocols",
                        str(now / "protocols"), "--jobs", "2", *(["--participants", "3"] if quick else [])],
                       check=True, capture_output=True, text=True, env=_env(now), cwd=now)
    return data


def run(out_dir: Path, quick: bool) -> str:
    title = f"## The simulated sessions' stream rebuild: {BEFORE_REV} against this tree (bench_gaze_rebuild_vs_a9b7079)"
    with tempfile.TemporaryDirectory(prefix="psyop-bench-rebuild-") as tmp:
        scratch = Path(tmp)
        timed_runs = alternate(BEFORE_REV, scratch, quick, 2, _TIMER)
        if timed_runs is None:
            return f"{title}\n\nSkipped: commit {BEFORE_REV} is not in this clone."
        runs, load = timed_runs
        bad = _equal_streams(scratch / "before", scratch / "now")
        load_after = os.getloadavg()[0]
    if bad:
        raise AssertionError(f"bench_gaze_rebuild_vs_a9b7079: rebuilt streams differ between {BEFORE_REV} and this "
                             f"tree: {bad}")
    first = runs["now"][0]
    return "\n".join([
        title, "",
        f"{first['sessions']} sessions, {first['samples']:,} rebuilt samples (streams: {', '.join(first['streams'])}); "
        f"each tree twice, alternating; the smaller of its two runs. Load average (1 min) {load:.1f} before, "
        f"{load_after:.1f} after (on {os.cpu_count()} CPUs). Every rebuilt stream equal, bit for bit.", "",
        *best_table(BEFORE_REV, runs),
    ])


if __name__ == "__main__":
    print(run(Path("bench"), "--quick" in sys.argv))
