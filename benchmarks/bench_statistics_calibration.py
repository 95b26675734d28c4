"""Calibration at larger simulation counts than CI affords.

- 95 % CI coverage at 15, 200, 1,000 and 10,000 trials per level (tests use 120 per count).
- Threshold recovery on >= 300 observers including shallow and lapsing ones: statuses, flags,
  and the count of unflagged infinite or extrapolated values (must be 0).
- Type I error of the GG-corrected 3x3 rm-ANOVA under non-spherical null data (tests use 150),
  and of the condition-interaction regression (tests use 120). Rates come with exact
  binomial 95 % intervals.
"""

from __future__ import annotations

import time
from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.stats import binomtest

from psyop.statistics.anova import rm_anova
from psyop.statistics.psychometric import FitOptions, fit_many
from psyop.statistics.regression import condition_interaction
from psyop.statistics.simulate import DETECTION_LEVELS_D, pc_2afc, simulate_reach, true_t75


def _rate(hits: np.ndarray) -> str:
    k, n = int(hits.sum()), hits.size
    ci = binomtest(k, n).proportion_ci()
    return f"{k / n:.3f} [{ci.low:.3f}, {ci.high:.3f}]"


def _null_two_way(rng, n_subjects=12):
    rows = []
    for s in range(n_subjects):
        u, slope = rng.normal(0, 1), rng.normal(0, 1.0)
        for i in range(3):
            for j in range(3):
                rows.append({"participant": f"s{s}", "A": f"a{i}", "B": f"b{j}",
                             "y": u + slope * (i - 1) * (j - 1) + slope * (i - 1) + rng.normal(0, 0.4)})
    return pd.DataFrame(rows)


def _silent(fit) -> bool:
    """An infinite or out-of-range value that carries no flag."""
    if np.isfinite(fit.threshold_D) and not fit.level_min_D <= fit.threshold_D <= fit.level_max_D:
        return True
    if fit.status == "ok" and (not np.isfinite(fit.threshold_ci_high_D) or not np.isfinite(fit.threshold_ci_low_D)):
        return True
    if fit.status == "ok" and fit.threshold_ci_high_D > fit.level_max_D and "ci_above_range" not in fit.flags:
        return True
    return fit.status == "ok" and fit.threshold_ci_low_D < fit.level_min_D and "ci_below_range" not in fit.flags


def _recovery(rng, n: int) -> str:
    """Observers with threshold U(0.1, 0.8) D, sd 0.1/0.2/0.5 D (shallow), lapse 0/0.03/0.08."""
    lv = np.array(DETECTION_LEVELS_D)
    truths, data = [], []
    for i in range(n):
        sigma, lapse, thr = (0.1, 0.2, 0.5)[i % 3], (0.0, 0.03, 0.08)[(i // 3) % 3], rng.uniform(0.1, 0.8)
        truths.append(true_t75(thr, sigma, lapse))
        data.append(np.c_[lv, rng.binomial(15, pc_2afc(lv, thr, sigma, lapse)), np.full(5, 15)])
    fits = fit_many(data, FitOptions(n_bootstrap=0, estimate_eta=False), n_jobs=2)
    truths = np.array(truths)
    statuses = Counter(f.status for f in fits)
    silent = sum(_silent(f) for f in fits)
    usable = np.array([f.usable for f in fits])
    est = np.array([f.threshold_D for f in fits])
    cover = np.array([f.threshold_ci_low_D <= t <= f.threshold_ci_high_D for f, t in zip(fits, truths)])
    flags = Counter(fl for f in fits for fl in f.flags if fl not in statuses)
    return (f"- recovery, {n} observers (threshold U(0.1, 0.8) D; sd 0.1/0.2/0.5 D; lapse 0/0.03/0.08; 5 levels x 15): "
            f"statuses {dict(sorted(statuses.items()))}; other flags {dict(sorted(flags.items()))}; "
            f"**unflagged infinite or extrapolated values: {silent}**; usable fits: bias "
            f"{np.mean(est[usable] - truths[usable]):+.4f} D, RMSE {np.sqrt(np.mean((est[usable] - truths[usable]) ** 2)):.3f} D; "
            f"CI coverage over all fits {_rate(cover)}")


def run(out_dir: Path, quick: bool) -> str:
    rng = np.random.default_rng(2026)
    n_fit, n_null = (200, 100) if quick else (1000, 1000)
    lv = np.array(DETECTION_LEVELS_D)
    lines = ["## statistics: calibration (recovery, type I error)", ""]
    truth = true_t75(0.36, 0.2, 0.0)
    p = pc_2afc(lv, 0.36, 0.2, 0.0)
    lines += ["95 % CI coverage of the true 75 % point across trials per level (5 levels, threshold 0.36 D, "
              f"sd 0.2 D, lapse 0; {n_fit} simulated observers per row; exact binomial 95 % interval of the rate):", "",
              "| trials per level | coverage | median CI width (D) | zero-width CIs | usable fits | wall s (2 processes) |",
              "|---|---|---|---|---|---|"]
    for n_per in (15, 200, 1000, 10000):
        data = [np.c_[lv, rng.binomial(n_per, p), np.full(5, n_per)] for _ in range(n_fit)]
        start = time.perf_counter()
        fits = fit_many(data, FitOptions(n_bootstrap=0, estimate_eta=False), n_jobs=2)
        wall = time.perf_counter() - start
        cover = np.array([f.threshold_ci_low_D <= truth <= f.threshold_ci_high_D for f in fits])
        width = np.array([f.ci_width_D for f in fits])
        lines.append(f"| {n_per} | {_rate(cover)} | {np.median(width):.4f} | {int((width <= 0).sum())} | "
                     f"{sum(f.usable for f in fits)} | {wall:.1f} |")
    lines += ["", _recovery(rng, 100 if quick else 600), ""]
    tables = [rm_anova(_null_two_way(rng), "y", ["A", "B"]).table for _ in range(n_null)]
    p_gg = np.array([t["p_gg"].to_numpy() for t in tables])
    p_unc = np.array([t["p_unc"].to_numpy() for t in tables])
    for k, eff in enumerate(tables[0]["effect"]):
        lines.append(f"- rm-ANOVA null (3x3, non-spherical, n=12), {eff}: GG rejection rate {_rate(p_gg[:, k] < 0.05)}, "
                     f"uncorrected {_rate(p_unc[:, k] < 0.05)}")
    same = {"enabled": (1.13, 0.166), "disabled": (1.13, 0.166)}
    rej = []
    for _ in range(n_null):
        d = simulate_reach(rng, lines=same, subject_sd=0.0)
        d["reach_fraction"] = d["reach_m"] / d["arm_reach_m"]
        rej.append(condition_interaction(d, "target_fraction", "reach_fraction", "rendering").joint_p < 0.05)
    lines.append(f"- condition-interaction regression null: joint F rejection rate {_rate(np.array(rej))}")
    return "\n".join(lines)
