"""One detection replication at 6 participants, on 81b52e2 (before issue 30) and on this tree,
side by side in one run: issue 30's goal is the replication at least 5x faster.

81b52e2's tree is extracted with ``git archive`` into a scratch folder; each measurement is a
fresh ``python -c`` child with ``PYTHONPATH`` on that tree or on this one (the venv is shared).
The child runs one warm-up replication (2 participants, replication 99: imports and caches are not
counted) and then replications 0..R-1 at 6 participants (seed 0), and reports the CPU time
(``time.process_time``: the child's own threads) and wall time per replication. Rounds alternate
old, new, old, new ... so load drifts hit both alike; the table gives each round, the ratio of
medians and the ratio of the fastest replications (best-of: what load on a shared machine inflates least). Each tree runs its own protocols/detection.yaml (the protocol schema changed since); the
outcomes (p values) of both trees are compared and the table says whether they are identical.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tarfile
import tempfile
from io import BytesIO
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
BEFORE_REV = "81b52e2"
CHILD = r"""
import json, sys, time
from pathlib import Path
from psyop.power.replicate import ReplicationTask, run_replication
path = Path(sys.argv[1]); n = int(sys.argv[2]); reps = int(sys.argv[3])
text = path.read_text()
run_replication(ReplicationTask(text, str(path), (), 2, 99, 0))
cpu, wall, outcomes = [], [], []
for r in range(reps):
    c, w = time.process_time(), time.perf_counter()
    result = run_replication(ReplicationTask(text, str(path), (), n, r, 0))
    cpu.append(time.process_time() - c); wall.append(time.perf_counter() - w)
    outcomes.append([[o.test, repr(o.p)] for o in result.outcomes])
print(json.dumps({"cpu_s": cpu, "wall_s": wall, "outcomes": outcomes}))
"""


def _tree(rev: str, root: Path) -> Path | None:
    archive = subprocess.run(["git", "-C", str(REPO), "archive", rev], capture_output=True)
    if archive.returncode != 0:
        return None
    tree = root / rev
    with tarfile.open(fileobj=BytesIO(archive.stdout)) as tar:
        tar.extractall(tree)
    return tree


def _measure(tree: Path, n: int, reps: int) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    done = subprocess.run([sys.executable, "-c", CHILD, str(tree / "protocols" / "detection.yaml"), str(n), str(reps)],
                          env=env, cwd=tree, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"bench_power_vs_81b52e2: the child on {tree} failed:\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def run(out_dir: Path, quick: bool) -> str:
    n, reps, rounds = 6, (1 if quick else 3), (1 if quick else 3)
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="psyop-bench-81b52e2-") as scratch:
        old = _tree(BEFORE_REV, Path(scratch))
        if old is None:
            return f"## bench_power_vs_81b52e2\n\nskipped: {BEFORE_REV} is not in this clone"
        per = {"81b52e2": [], "this tree": []}
        outcomes = {}
        for _ in range(rounds):
            for label, tree in (("81b52e2", old), ("this tree", REPO)):
                got = _measure(tree, n, reps)
                per[label].append((got["cpu_s"], got["wall_s"]))
                outcomes[label] = got["outcomes"]
    load_after = os.getloadavg()[0]
    cpu = {k: statistics.median(c for cs, _ in v for c in cs) for k, v in per.items()}
    wall = {k: statistics.median(w for _, ws in v for w in ws) for k, v in per.items()}
    best = {k: min(c for cs, _ in v for c in cs) for k, v in per.items()}
    lines = ["## One detection replication at 6 participants: 81b52e2 vs this tree (bench_power_vs_81b52e2)", "",
             f"{rounds} interleaved rounds x {reps} replications (seed 0) each, one child process per round after a "
             f"warm-up replication; median per replication. Load average (1 min) {load_before:.2f} before, "
             f"{load_after:.2f} after.", "",
             "| tree | CPU s | wall s | fastest CPU s | per round (CPU s) |", "|---|---:|---:|---:|---|"]
    for label in per:
        rounds_text = "; ".join(", ".join(f"{c:.2f}" for c in cs) for cs, _ in per[label])
        lines.append(f"| {label} | {cpu[label]:.2f} | {wall[label]:.2f} | {best[label]:.2f} | {rounds_text} |")
    lines += ["", f"**CPU ratio 81b52e2 / this tree: {cpu['81b52e2'] / cpu['this tree']:.2f}x** "
              f"(wall {wall['81b52e2'] / wall['this tree']:.2f}x; fastest replications "
              f"{best['81b52e2'] / best['this tree']:.2f}x; goal 5x).",
              f"Outcomes (test, p value) identical on both trees: {outcomes['81b52e2'] == outcomes['this tree']}."]
    return "\n".join(lines)
