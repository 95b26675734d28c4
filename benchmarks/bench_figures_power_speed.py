"""`make figures`, the supplementary psychometric figure and `psyop power`: before and after issue 21's
work (parts 2-3), side by side in one run, on the same inputs, with their outputs compared.

"Before" is the tree of commit :data:`BEFORE_REV` (main before that work: one process per analysis
script, ``sharey`` panels, power fits with the free-eta posterior and the deviance bootstrap),
extracted with ``git archive`` and run with the same interpreter (``PYTHONPATH`` puts its psyop
first); "after" is the tree of :data:`AFTER_REV`, where that work landed, extracted alike: a later
change that alters outputs on purpose (the summary's agreement criterion, the reach fallback's
model, issue 29) leaves this comparison of issue 21's work as it was measured. Both run with ``SOURCE_DATE_EPOCH=0`` so that their PDFs carry the
same date. The benchmark fails when an output differs: every figure (PNG and PDF) and results
file of `make figures-build`, the supplementary figure's PNG, and `psyop power`'s power.csv must
be byte-identical. Times are wall seconds and the CPU seconds of the child processes
(user + system, less sensitive to other load on a shared machine); the claim is the ratio.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tarfile
import tempfile
import time
from io import BytesIO
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: main before the one-process figures, the linear psychometric grid and the lean power fits
BEFORE_REV = "2a9bf04"
#: main with that work landed (issue 21's stop)
AFTER_REV = "81b52e2"

_GRID_SCRIPT = """
import sys, time
import pandas as pd
from psyop.figures.output import save_figure
from psyop.figures.study_figures import plot_psychometric_grid
blocks = pd.read_csv(sys.argv[1], dtype={"participant": str}); fits = pd.read_csv(sys.argv[2], dtype={"participant": str, "flags": str},
                                                      keep_default_na=False, na_values=[""])
start = time.perf_counter()
fig = plot_psychometric_grid(blocks, fits, "back_D", "Psychometric functions", simulated=True)
save_figure(fig, sys.argv[3])
print(time.perf_counter() - start)
"""


def _tree(rev: str, root: Path) -> Path | None:
    """The tree of commit ``rev`` under ``root``; None when this clone does not hold it."""
    archive = subprocess.run(["git", "-C", str(REPO), "archive", rev], capture_output=True)
    if archive.returncode:
        return None
    with tarfile.open(fileobj=BytesIO(archive.stdout)) as tar:
        tar.extractall(root, filter="data")
    return root


def _env(tree: Path) -> dict[str, str]:
    env = {**os.environ, "SOURCE_DATE_EPOCH": "0", "MPLBACKEND": "Agg"}
    env.pop("PYTHONPATH", None)
    if tree != REPO:
        env["PYTHONPATH"] = str(tree)
    return env


def _timed(cmd: list[str], env: dict[str, str], cwd: Path) -> tuple[float, float, str]:
    """(wall s, child CPU s, stdout) of ``cmd``; a failure raises with its stderr."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode:
        raise RuntimeError(f"{' '.join(cmd[:6])}... exited {done.returncode}: {done.stderr[-2000:]}")
    return wall, (after.ru_utime - usage.ru_utime) + (after.ru_stime - usage.ru_stime), done.stdout


def _differing(a: Path, b: Path) -> list[str]:
    """Files under ``a`` and ``b`` (relative paths) that are not byte-identical or not in both."""
    names = {p.relative_to(a).as_posix() for p in a.rglob("*") if p.is_file()} | \
        {p.relative_to(b).as_posix() for p in b.rglob("*") if p.is_file()}
    names.discard("results/.studies.mk")  # the make rules, which name the runner
    return sorted(n for n in names if not ((a / n).is_file() and (b / n).is_file()
                                           and (a / n).read_bytes() == (b / n).read_bytes()))


def _figures(trees: dict[str, Path], scratch: Path, jobs: int) -> dict[str, tuple[float, float]]:
    times = {}
    for label, tree in trees.items():
        out = scratch / label
        cmd = ["make", "--no-print-directory", "-C", str(tree), "figures-build", f"PY={sys.executable}",
               f"DATA={scratch / 'data'}", f"RESULTS={out / 'results'}", f"FIGDIR={out / 'figures'}", f"JOBS={jobs}"]
        wall, cpu, _ = _timed(cmd, _env(tree), tree)
        times[label] = (wall, cpu)
    differing = _differing(scratch / "before", scratch / "after")
    if differing:
        raise AssertionError(f"bench_figures_power_speed: make figures-build before and after differ in {differing}")
    return times


def _grid(trees: dict[str, Path], scratch: Path, sizes: tuple[int, ...]) -> list[tuple[int, dict[str, float]]]:
    import numpy as np

    from psyop.statistics import simulate
    from psyop.statistics.psychometric import FitOptions, GridSpec, fit_psychometric_table

    rows = []
    for n in sizes:
        trials = simulate.simulate_detection(np.random.default_rng(n), n)
        fits = fit_psychometric_table(trials, "level_D", ["participant", "back_D"], n_jobs=1, options=FitOptions(
            grid=GridSpec().scaled(0.5), n_bootstrap=0, estimate_eta=False))  # real fits, cheaply: the drawing is timed
        blocks = (trials.groupby(["participant", "back_D", "level_D"])["correct"].agg(["sum", "size"])
                  .rename(columns={"sum": "n_correct", "size": "n_total"}).reset_index())
        blocks.to_csv(scratch / f"blocks_{n}.csv", index=False)
        fits.to_csv(scratch / f"fits_{n}.csv", index=False)
        seconds = {}
        for label, tree in trees.items():
            png = scratch / f"grid_{label}_{n}.png"
            _, _, out = _timed([sys.executable, "-c", _GRID_SCRIPT, str(scratch / f"blocks_{n}.csv"),
                                str(scratch / f"fits_{n}.csv"), str(png)], _env(tree), tree)
            seconds[label] = float(out.strip().splitlines()[-1])
        if (scratch / f"grid_before_{n}.png").read_bytes() != (scratch / f"grid_after_{n}.png").read_bytes():
            raise AssertionError(f"bench_figures_power_speed: the psychometric grid at {n} participants differs")
        rows.append((n, seconds))
    return rows


def _power(trees: dict[str, Path], scratch: Path, participants: int, replications: int) -> dict[str, tuple[float, float]]:
    times = {}
    for label, tree in trees.items():
        cmd = [sys.executable, "-m", "psyop", "power", "protocols/detection.yaml", "--participants", str(participants),
               "--replications", str(replications), "--seed", "0", "--jobs", "1", "--no-checkpoint",
               "--out", str(scratch / f"power_{label}")]
        wall, cpu, _ = _timed(cmd, _env(tree), tree)
        times[label] = (wall, cpu)
    before, after = (scratch / f"power_{k}" / "power.csv" for k in ("before", "after"))
    if before.read_bytes() != after.read_bytes():
        raise AssertionError("bench_figures_power_speed: psyop power's power.csv differs before and after")
    return times


def _row(what: str, times: dict[str, tuple[float, float]]) -> str:
    (bw, bc), (aw, ac) = times["before"], times["after"]
    return f"| {what} | {bw:.1f} | {aw:.1f} | {bw / aw:.2f} | {bc:.1f} | {ac:.1f} | {bc / ac:.2f} |"


def run(out_dir: Path, quick: bool) -> str:
    jobs = 2
    participants = 3 if quick else None  # an rm-ANOVA over three levels needs three
    sizes = (2, 4) if quick else (6, 20, 60)
    power_n, power_reps = (2, 1) if quick else (4, 4)
    title = "## Figures and power without repeated work: before and after (bench_figures_power_speed)"
    with tempfile.TemporaryDirectory(prefix="psyop-bench-speed-") as tmp:
        scratch = Path(tmp)
        before, after = _tree(BEFORE_REV, scratch / "before-tree"), _tree(AFTER_REV, scratch / "after-tree")
        if before is None or after is None:
            return f"{title}\n\nSkipped: commit {BEFORE_REV} or {AFTER_REV} (the trees compared) is not in this clone."
        trees = {"before": before, "after": after}
        subprocess.run([sys.executable, "-m", "psyop", "simulate", "--data", str(scratch / "data"), "--protocols",
                        str(after / "protocols"), "--jobs", str(jobs),
                        *(["--participants", str(participants)] if participants else [])],
                       check=True, capture_output=True, text=True, env=_env(after), cwd=after)
        figures = _figures(trees, scratch, jobs)
        grid = _grid(trees, scratch, sizes)
        power = _power(trees, scratch, power_n, power_reps)
    size = "3 participants per study (quick)" if quick else "the paper's sizes (6/6/19/13/19 participants)"
    lines = [
        title, "",
        f"Before: commit {BEFORE_REV}; after: commit {AFTER_REV}; same interpreter, inputs and seeds, run one after the other.",
        "Every output compared byte for byte (the benchmark fails otherwise): all figures (PNG, PDF) and results",
        "files of `make figures-build`, the psychometric grid PNG, `psyop power`'s power.csv.", "",
        "| what | before wall s | after wall s | wall ratio | before CPU s | after CPU s | CPU ratio |",
        "|---|---|---|---|---|---|---|",
        _row(f"make figures-build, simulated data at {size}, JOBS={jobs}", figures),
        _row(f"psyop power protocols/detection.yaml --participants {power_n} --replications {power_reps} --jobs 1",
             power),
        "",
        "Supplementary psychometric figure (plot_psychometric_grid + save_figure, PNG and PDF; detection, 3 conditions",
        "per participant):", "",
        "| participants | panels | before s | after s | before s per participant | after s per participant |",
        "|---|---|---|---|---|---|",
    ]
    for n, s in grid:
        lines.append(f"| {n} | {3 * n} | {s['before']:.2f} | {s['after']:.2f} | {s['before'] / n:.3f} | "
                     f"{s['after'] / n:.3f} |")
    (n0, s0), (n1, s1) = grid[0], grid[-1]
    lines += ["", f"Growth from {n0} to {n1} participants ({n1 / n0:.0f}x): before {s1['before'] / s0['before']:.1f}x, "
              f"after {s1['after'] / s0['after']:.1f}x (linear: {n1 / n0:.0f}x)."]
    return "\n".join(lines)
