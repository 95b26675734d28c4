"""Calibration at larger simulation counts than CI affords.

- Threshold recovery at the detection design (5 levels x 15 trials): bias, RMSE and 95 % CI
  coverage of the default grid over many simulated observers (tests use 200).
- Type I error of the GG-corrected 3x3 rm-ANOVA under non-spherical null data (tests use 150),
  and of the condition-interaction regression (tests use 120). Rates come with exact
  binomial 95 % intervals.
"""

from __future__ import annotations

import time
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


def run(out_dir: Path, quick: bool) -> str:
    rng = np.random.default_rng(2026)
    n_fit, n_null = (200, 100) if quick else (1000, 1000)
    lv = np.array(DETECTION_LEVELS_D)
    lines = ["## statistics: calibration (recovery, type I error)", ""]
    for lapse in (0.0, 0.03):
        truth = true_t75(0.36, 0.2, lapse)
        p = pc_2afc(lv, 0.36, 0.2, lapse)
        data = [np.c_[lv, rng.binomial(15, p), np.full(5, 15)] for _ in range(n_fit)]
        start = time.perf_counter()
        fits = fit_many(data, FitOptions(n_bootstrap=0), n_jobs=2)
        wall = time.perf_counter() - start
        est = np.array([f.threshold_D for f in fits])
        cover = np.array([f.threshold_ci_low_D <= truth <= f.threshold_ci_high_D for f in fits])
        lines.append(f"- recovery, lapse {lapse}: {n_fit} datasets, true 75 % point {truth:.3f} D, "
                     f"bias {est.mean() - truth:+.4f} D (SE {est.std(ddof=1) / np.sqrt(n_fit):.4f}), "
                     f"RMSE {np.sqrt(np.mean((est - truth) ** 2)):.3f} D, 95 % CI coverage {_rate(cover)}, "
                     f"{wall:.1f} s wall on 2 processes")
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
