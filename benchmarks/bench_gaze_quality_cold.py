"""The cold gaze-quality path of ``make figures-build`` (what an empty quality cache costs): every simulated
session of the paper-sized data measured by :func:`psyop.quality.session.measured_session` (verify, read,
rebuild the requested stream from its seed and check it, detect events with pymovements, the per-trial
measures) on the code at :data:`BEFORE_REV` and on this tree, side by side in one run.

Each tree runs in a process of its own (``PYTHONPATH`` puts its psyop first; the same interpreter and data),
its imports and a warm-up session outside the timing, then every session once, the compiled plans shared as
the figures build shares them; the trees alternate (twice each; once with ``--quick``) and the table gives each
tree's CPU and wall seconds (the smaller of its runs) and the ratio. Every (measures, events) table of every
session must be the same in the two trees (the benchmark fails otherwise): the same columns, dtypes and rows;
numbers equal to rtol 1e-9 and atol 1e-12 (NaN equal to NaN), everything else exactly; the report says how
many numeric columns were equal bit for bit. The data: ``PSYOP_BENCH_FIGURES_DATA`` when set (as
:mod:`benchmarks.bench_figures_vs_c57032f`: simulated there when it holds no session; only read here), else
a scratch folder simulated here (``--quick``: 3 participants per study).
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

from benchmarks.bench_gaze_rebuild_vs_a9b7079 import alternate, best_table

#: the code before the session-wide trial measures
BEFORE_REV = "27a0aec"

#: tolerances of the table comparison (numbers); everything else must be equal exactly
RTOL, ATOL = 1e-9, 1e-12

#: run in each tree's process: time measured_session over every session, write each session's two tables
_TIMER = """
import json, sys, time
from pathlib import Path
from psyop.quality.session import measured_session
data, out = Path(sys.argv[1]), Path(sys.argv[2])
sessions = sorted(p.parent for p in data.glob("*/sub-*/ses-*/trials.parquet"))
measured_session(sessions[0])  # imports and first-use costs outside the timing
plans, cpu, wall, tables = {}, time.process_time(), time.perf_counter(), []
for d in sessions:
    tables.append(measured_session(d, plans))
cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
if len(sys.argv) > 3:
    out.mkdir(parents=True, exist_ok=True)
    for i, (measures, events) in enumerate(tables):
        measures.to_parquet(out / f"{i:03d}_measures.parquet")
        events.to_parquet(out / f"{i:03d}_events.parquet")
print(json.dumps({"cpu_s": cpu, "wall_s": wall, "sessions": len(sessions),
                  "trials": int(sum(len(m) for m, _ in tables)), "events": int(sum(len(e) for _, e in tables))}))
"""


def compare_tables(a: Path, b: Path) -> tuple[list[str], int, int]:
    """(what differs, numeric columns compared, of them equal bit for bit) between the tables two trees wrote
    (``NNN_measures.parquet``, ``NNN_events.parquet``): columns, dtypes and lengths equal; numbers to
    :data:`RTOL`/:data:`ATOL` with NaN equal to NaN; every other column exactly."""
    import numpy as np
    import pandas as pd

    names = sorted(p.name for p in a.glob("*.parquet"))
    if not names or names != sorted(p.name for p in b.glob("*.parquet")):
        return ["the two trees wrote different (or no) session tables"], 0, 0
    bad, n_numeric, n_exact = [], 0, 0
    for name in names:
        x, y = pd.read_parquet(a / name), pd.read_parquet(b / name)
        if list(x.columns) != list(y.columns) or list(x.dtypes) != list(y.dtypes) or len(x) != len(y):
            bad.append(f"{name}: columns, dtypes or length")
            continue
        for column in x.columns:
            u, v = x[column].to_numpy(), y[column].to_numpy()
            if u.dtype.kind in "fiu":
                n_numeric += 1
                n_exact += bool(np.array_equal(u, v, equal_nan=u.dtype.kind == "f"))
                same = np.allclose(u.astype(float), v.astype(float), rtol=RTOL, atol=ATOL, equal_nan=True)
            else:
                same = len(u) == len(v) and all(p == q or (p != p and q != q) for p, q in zip(u.tolist(), v.tolist()))
            if not same:
                bad.append(f"{name}: {column}")
    return bad, n_numeric, n_exact


def run(out_dir: Path, quick: bool) -> str:
    title = f"## The cold gaze-quality path: {BEFORE_REV} against this tree (bench_gaze_quality_cold)"
    with tempfile.TemporaryDirectory(prefix="psyop-bench-quality-cold-") as tmp:
        scratch = Path(tmp)
        timed_runs = alternate(BEFORE_REV, scratch, quick, 1 if quick else 2, _TIMER)
        if timed_runs is None:
            return f"{title}\n\nSkipped: commit {BEFORE_REV} is not in this clone."
        runs, load = timed_runs
        bad, n_numeric, n_exact = compare_tables(scratch / "before", scratch / "now")
        load_after = os.getloadavg()[0]
    if bad:
        raise AssertionError(f"bench_gaze_quality_cold: the quality tables differ between {BEFORE_REV} and this "
                             f"tree: {bad[:20]}")
    first = runs["now"][0]
    return "\n".join([
        title, "",
        f"{first['sessions']} sessions, {first['trials']:,} trials, {first['events']:,} events; each tree "
        f"{len(runs['now'])} time(s), alternating; the smaller of its runs. Load average (1 min) {load:.1f} before, "
        f"{load_after:.1f} after (on {os.cpu_count()} CPUs). Every table the same (numbers to rtol {RTOL:g}, "
        f"atol {ATOL:g}; {n_exact} of {n_numeric} numeric columns bit for bit).", "",
        *best_table(BEFORE_REV, runs),
    ])


if __name__ == "__main__":
    print(run(Path("bench"), "--quick" in sys.argv))
