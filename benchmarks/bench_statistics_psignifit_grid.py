"""psignifit grid resolution vs threshold error (against a fine-grid reference) and time per fit.

Detection design (5 levels x 15 trials, threshold 0.36 D, sd 0.2 D, lapse 0.02). For each
grid the 75 % threshold and its 95 % interval are compared with a 3x-finer grid on the same
datasets; time per fit is measured side by side in this run. The public
``psignifit.psignifit`` (default grid + Nelder-Mead MAP) is timed on a few datasets for the ratio.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np
import psignifit

from psyop.statistics.psychometric import (
    PSIGNIFIT_DEFAULT_GRID, FitOptions, GridSpec, fit_psychometric, grid_posterior,
)
from psyop.statistics.simulate import DETECTION_LEVELS_D, pc_2afc

SCALES = (0.4, 0.6, 0.8, 1.0, 1.5, 2.0)


def _datasets(n: int, seed: int = 99) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    lv = np.array(DETECTION_LEVELS_D)
    p = pc_2afc(lv, 0.36, 0.2, 0.02)
    return [np.c_[lv, rng.binomial(15, p), np.full(5, 15)] for _ in range(n)]


def _run(datasets, grid: GridSpec):
    opts = FitOptions(grid=grid, n_bootstrap=0, estimate_eta=False)
    start = time.process_time()
    fits = [fit_psychometric(d, opts) for d in datasets]
    per_fit = (time.process_time() - start) / len(datasets)
    arr = np.array([[f.threshold_D, f.threshold_ci_low_D, f.threshold_ci_high_D] for f in fits])
    return arr, per_fit, grid_posterior(datasets[0], opts).posterior.size


def run(out_dir: Path, quick: bool) -> str:
    datasets = _datasets(8 if quick else 24)
    ref, ref_time, ref_points = _run(datasets, GridSpec().scaled(3.0))
    rows = []
    grids = [(f"psyop x{s:g}", GridSpec().scaled(s)) for s in SCALES] + [("psignifit default", PSIGNIFIT_DEFAULT_GRID)]
    for name, grid in grids:
        arr, per_fit, points = _run(datasets, grid)
        err = np.abs(arr - ref)
        rows.append((name, points, per_fit, err[:, 0].mean(), err[:, 0].max(), err[:, 1:].mean()))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        n_pub = 2 if quick else 4
        start = time.process_time()
        pub = [psignifit.psignifit(d, experiment_type="2AFC", sigmoid="norm", verbose=False) for d in datasets[:n_pub]]
        pub_time = (time.process_time() - start) / n_pub
    pub_err = np.mean([abs(float(r.threshold(0.75, return_ci=False)) - ref[i, 0]) for i, r in enumerate(pub)])
    default_time = next(r[2] for r in rows if r[0] == "psyop x1")
    lines = [
        "## statistics: psignifit grid resolution vs threshold error and time",
        "",
        f"{len(datasets)} simulated detection datasets (5 levels x 15 trials). Reference: psyop grid x3 "
        f"({ref_points} dense points, {ref_time * 1e3:.0f} ms CPU per fit). "
        "Errors are |threshold - reference| in D; CI error is the mean over both 95 % bounds. "
        "Eta fixed to 0 (psyop's default for thresholds), so the dense grid is threshold x width x lambda.",
        "",
        "| grid | dense points | CPU ms / fit | ratio to x1 | mean err (D) | max err (D) | mean CI-bound err (D) |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, pts, t, me, mx, ce in rows:
        lines.append(f"| {name} | {pts} | {t * 1e3:.0f} | {t / default_time:.2f} | {me:.4f} | {mx:.4f} | {ce:.4f} |")
    lines += [
        "",
        f"Public `psignifit.psignifit` (default grid + Nelder-Mead MAP, `res.threshold(0.75)`): "
        f"{pub_time * 1e3:.0f} ms CPU per fit = {pub_time / default_time:.1f}x psyop's default; "
        f"mean |threshold - reference| = {pub_err:.4f} D on {n_pub} datasets.",
        "",
        "Read the knee off the table: psyop's default is x1 (GridSpec()); the thresholds' own 95 % "
        "intervals are ~0.4-0.5 D wide, so errors of a few thousandths of a diopter are immaterial.",
    ]
    return "\n".join(lines)
