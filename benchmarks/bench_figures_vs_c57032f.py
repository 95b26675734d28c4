"""`make figures-build` on the code at c57032f (before the gaze-quality work) and on this tree, side by side in
one run, from the same simulated data: issue 43's goal is this tree at least 2x faster, every gaze measure kept.

The paper-sized dataset (all five studies, the paper's participant counts) is simulated once, by this tree,
into a scratch data root. Then `make figures-build` runs, one after the other, with the same interpreter,
``JOBS`` and data, each into its own scratch results/figures folders:

- ``c57032f``: that commit's tree, extracted with ``git archive`` (``PYTHONPATH`` puts its psyop first);
- ``start``: the tree of :data:`START_REV` (main before the gaze-quality cache and vectorisation), alike;
- ``now``: this tree (a copy, when given one), its gaze-quality cache (the data root's .psyop-cache, which
  the former trees neither read nor write) empty: it fills as the build goes (a study's sessions measured
  twice, by its quality: rules and by its gaze-quality figure, are measured once);
- ``now (cached)``: this tree again into emptied results/figures folders, the cache kept: every figure and
  table rebuilt with the sessions' gaze quality already measured (what a change to an analysis or drawing
  script costs; context, not the cold claim);
- ``now (cached, JOBS=1)``: the same with ``JOBS=1``, every script in one process (what the build's
  independent parts gain from running side by side in JOBS processes, analysis/batch.py ``--jobs``).

``PSYOP_BENCH_FIGURES_DATA=DIR`` keeps the simulated data in DIR and reuses it in later runs (simulated there
only when DIR holds no session; the quality cache under it is emptied before the builds, so the cold build is
cold); without it the data root is scratch, simulated anew each run.

Outputs compared: every results/ CSV the two builds share is compared column by column (the columns both have;
numbers to :data:`RTOL` relative and :data:`ATOL` absolute, NaN equal to NaN; anything else exactly), and the
files and columns only one build has are listed. ``start`` against ``now`` is the gaze-measure check: every
results/<study>_gaze_quality.csv and _gaze_events.csv of all sessions must agree and the gaze-quality figures
(the measures and the samples drawn) must be byte-identical (the benchmark fails otherwise; every other figure
that differs is listed); c57032f against ``now`` is reported (c57032f has no gaze-quality outputs and the statistics changed
on purpose since: the differing files are listed, not failed). Times are wall seconds and the CPU seconds of
the child processes (user + system); the claim is the wall ratio of the cold runs.
"""

from __future__ import annotations

import os
import resource
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
from io import BytesIO
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]
#: the code the issue compares against (before the gaze-quality work)
BASE_REV = "c57032f"
#: main before the gaze-quality cache and the vectorised measures (the reference for every gaze measure)
START_REV = "606a4d0"
#: tolerances for numbers in the compared CSVs
RTOL, ATOL = 1e-9, 1e-12
#: the environment variable naming a data root to keep and reuse between runs (module docstring)
DATA_ENV = "PSYOP_BENCH_FIGURES_DATA"


def _tree(rev: str, root: Path) -> Path | None:
    """The tree of commit ``rev`` under ``root``; None when this clone does not hold it."""
    archive = subprocess.run(["git", "-C", str(REPO), "archive", rev], capture_output=True)
    if archive.returncode:
        return None
    with tarfile.open(fileobj=BytesIO(archive.stdout)) as tar:
        tar.extractall(root, filter="data")
    return root


def _copy_tree(root: Path) -> Path:
    """This working tree's files (tracked and untracked, not ignored) copied under ``root``: what is measured
    does not change while the benchmark runs (nor its quality cache's code key between the cold and cached builds)."""
    listed = subprocess.run(["git", "-C", str(REPO), "ls-files", "-z", "-c", "-o", "--exclude-standard"],
                            capture_output=True, check=True).stdout.decode().split("\0")
    for name in filter(None, listed):
        source = REPO / name
        if source.is_file():
            (root / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, root / name)
    return root


def _env(tree: Path) -> dict[str, str]:
    return {**os.environ, "SOURCE_DATE_EPOCH": "0", "MPLBACKEND": "Agg", "PYTHONPATH": str(tree)}


def _timed(cmd: list[str], env: dict[str, str], cwd: Path) -> tuple[float, float]:
    """(wall s, child CPU s) of ``cmd``; a failure raises with its stderr."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode:
        raise RuntimeError(f"{' '.join(cmd[:6])}... exited {done.returncode}: {done.stderr[-3000:]}")
    return wall, (after.ru_utime - usage.ru_utime) + (after.ru_stime - usage.ru_stime)


def _build(tree: Path, data: Path, out: Path, jobs: int) -> tuple[float, float]:
    cmd = ["make", "--no-print-directory", "-C", str(tree), "figures-build", f"PY={sys.executable}",
           f"DATA={data}", f"RESULTS={out / 'results'}", f"FIGDIR={out / 'figures'}", f"JOBS={jobs}"]
    return _timed(cmd, _env(tree), tree)


def _frames_differ(a: pd.DataFrame, b: pd.DataFrame) -> str:
    """'' when ``a`` and ``b`` agree on their shared columns (numbers to RTOL/ATOL), else what differs."""
    if len(a) != len(b):
        return f"{len(a)} vs {len(b)} rows"
    bad = []
    for col in [c for c in a.columns if c in b.columns]:
        x, y = a[col], b[col]
        if pd.api.types.is_numeric_dtype(x) and pd.api.types.is_numeric_dtype(y):
            xv, yv = x.to_numpy(dtype=float), y.to_numpy(dtype=float)
            if not np.allclose(xv, yv, rtol=RTOL, atol=ATOL, equal_nan=True):
                worst = np.nanmax(np.abs(xv - yv)) if np.isfinite(xv - yv).any() else float("nan")
                bad.append(f"{col} (max |diff| {worst:.3g})")
        elif not x.astype(str).equals(y.astype(str)):
            bad.append(col)
    return ", ".join(bad)


def compare_results(a: Path, b: Path) -> dict[str, list[str]]:
    """The CSVs of results folders ``a`` and ``b``: ``only_a``/``only_b`` (files), ``equal``, ``differ``
    (file: what) and ``columns`` (file: the columns only one has)."""
    names_a = {p.name for p in a.glob("*.csv")}
    names_b = {p.name for p in b.glob("*.csv")}
    report: dict[str, list[str]] = {"only_a": sorted(names_a - names_b), "only_b": sorted(names_b - names_a),
                                    "equal": [], "differ": [], "columns": []}
    for name in sorted(names_a & names_b):
        fa, fb = pd.read_csv(a / name), pd.read_csv(b / name)
        extra = sorted(set(fa.columns) ^ set(fb.columns))
        if extra:
            report["columns"].append(f"{name}: {extra}")
        what = _frames_differ(fa, fb)
        report["differ" if what else "equal"].append(f"{name}: {what}" if what else name)
    return report


def differing_figures(a: Path, b: Path) -> list[str]:
    """The figure files (PNG, PDF) of folders ``a`` and ``b`` that are not byte-identical or not in both."""
    names = {p.name for p in a.iterdir()} | {p.name for p in b.iterdir()}
    return sorted(n for n in names if not ((a / n).is_file() and (b / n).is_file()
                                           and (a / n).read_bytes() == (b / n).read_bytes()))


def _clear_outputs(out: Path) -> None:
    """Delete every output under ``out`` (the results and figures folders)."""
    shutil.rmtree(out / "figures", ignore_errors=True)
    shutil.rmtree(out / "results", ignore_errors=True)


def _data_root(scratch: Path, now: Path, jobs: int, quick: bool) -> Path:
    """The simulated data the builds read: :data:`DATA_ENV`'s folder when set (simulated only when it holds no
    session), else ``scratch``/data, simulated by ``now``; its quality cache emptied (the cold build is cold)."""
    kept = os.environ.get(DATA_ENV)
    data = Path(kept).resolve() if kept else scratch / "data"
    if not any(data.glob("*/sub-*/ses-*/trials.parquet")):
        participants = ["--participants", "3"] if quick else []  # an rm-ANOVA over three levels needs three
        subprocess.run([sys.executable, "-m", "psyop", "simulate", "--data", str(data), "--protocols",
                        str(now / "protocols"), "--jobs", str(jobs), *participants],
                       check=True, capture_output=True, text=True, env=_env(now), cwd=now)
    shutil.rmtree(data / ".psyop-cache", ignore_errors=True)
    return data


def _builds(trees: dict[str, Path], scratch: Path, data: Path,
            jobs: int) -> tuple[dict[str, tuple[float, float]], dict]:
    """The times of each tree's build and of this tree's cached rebuild (in JOBS processes, then in one, whose
    outputs must be the same), and the comparison of ``start``'s results with the cold build's (made before
    the rebuild replaces them)."""
    times = {label: _build(tree, data, scratch / label, jobs) for label, tree in trees.items()}
    cold = compare_results(scratch / "start" / "results", scratch / "now" / "results")
    cold["figures"] = differing_figures(scratch / "start" / "figures", scratch / "now" / "figures")
    _clear_outputs(scratch / "now")
    times["now (cached)"] = _build(trees["now"], data, scratch / "now", jobs)
    serial = scratch / "now-serial"
    times["now (cached, JOBS=1)"] = _build(trees["now"], data, serial, 1)
    _same_in_one_process(compare_results(serial / "results", scratch / "now" / "results"),
                         differing_figures(serial / "figures", scratch / "now" / "figures"))
    return times, cold


def _same_in_one_process(report: dict[str, list[str]], figures: list[str]) -> None:
    """Fail unless the build in one process (JOBS=1) and in JOBS processes wrote the same tables and
    byte-identical figures."""
    bad = report["differ"] + report["only_a"] + report["only_b"] + report["columns"] + figures
    if bad:
        raise AssertionError(f"bench_figures_vs_c57032f: JOBS=1 and JOBS=2 builds differ: {bad}")


def _gaze_check(report: dict[str, list[str]]) -> None:
    """Fail when a gaze-quality CSV of ``start`` and ``now`` differs or is missing from one."""
    gaze = ("_gaze_quality.csv", "_gaze_events.csv")
    bad = [f for f in report["differ"] + report["only_a"] + report["only_b"] + report["columns"]
           if any(g in f.split(":")[0] for g in gaze)]
    bad += [f for f in report.get("figures", []) if "_gaze_quality" in f]  # the measures and samples figures
    if bad:
        raise AssertionError(f"bench_figures_vs_c57032f: the gaze measures of {START_REV} and this tree differ: {bad}")


def _table(times: dict[str, tuple[float, float]], jobs: int, size: str) -> list[str]:
    bw, bc = times["c57032f"]
    lines = [f"`make figures-build`, simulated data at {size}, JOBS={jobs}, one after the other in this order:", "",
             "| code | wall s | CPU s | c57032f / this (wall) | c57032f / this (CPU) |", "|---|---|---|---|---|"]
    for label, (w, c) in times.items():
        lines.append(f"| {label} | {w:.1f} | {c:.1f} | {bw / w:.2f} | {bc / c:.2f} |")
    return lines


def _listing(title: str, report: dict[str, list[str]]) -> list[str]:
    return [f"{title}: {len(report['equal'])} CSVs equal; differ: {report['differ'] or 'none'}; "
            f"only in the first: {report['only_a'] or 'none'}; only in the second: {report['only_b'] or 'none'}; "
            f"columns only one has: {report['columns'] or 'none'}"
            + (f"; figures not byte-identical: {report['figures'] or 'none'}." if "figures" in report else ".")]


def run(out_dir: Path, quick: bool, now: Path | None = None) -> str:
    """The report; ``now``: the tree measured as this one (default: a copy of this working tree, so that edits
    during the run do not change what is measured)."""
    jobs = 2
    title = "## make figures-build: c57032f against this tree (bench_figures_vs_c57032f)"
    with tempfile.TemporaryDirectory(prefix="psyop-bench-c57032f-") as tmp:
        scratch = Path(tmp)
        base, start = _tree(BASE_REV, scratch / "base-tree"), _tree(START_REV, scratch / "start-tree")
        if base is None or start is None:
            return f"{title}\n\nSkipped: commit {BASE_REV} or {START_REV} is not in this clone."
        now = now or _copy_tree(scratch / "now-tree")
        load = os.getloadavg()[0]
        data = _data_root(scratch, now, jobs, quick)
        times, gaze = _builds({"c57032f": base, "start": start, "now": now}, scratch, data, jobs)
        load_after = os.getloadavg()[0]
        _gaze_check(gaze)
        former = compare_results(scratch / "c57032f" / "results", scratch / "now" / "results")
        cached = compare_results(scratch / "start" / "results", scratch / "now" / "results")
        cached["figures"] = differing_figures(scratch / "start" / "figures", scratch / "now" / "figures")
        _gaze_check(cached)
    size = "3 participants per study (quick)" if quick else "the paper's sizes (6/6/19/13/19 participants)"
    return "\n".join([
        title, "",
        f"c57032f and {START_REV} extracted with git archive; this tree as it is; same interpreter, data and JOBS.",
        *_table(times, jobs, size), "",
        f"Load average (1 min) before the builds {load:.1f}, after {load_after:.1f} (on {os.cpu_count()} CPUs).", "",
        *_listing(f"{START_REV} vs this tree (cold)", gaze),
        *_listing(f"{START_REV} vs this tree (cached)", cached),
        *_listing("c57032f vs this tree", former),
    ])


if __name__ == "__main__":
    print(run(Path("bench"), "--quick" in sys.argv))
