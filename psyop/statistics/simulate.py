"""Simulated trial tables with known effects, in the trials.parquet layout.

For tests, power analysis and parameter recovery of the statistics only: the session
package simulates whole sessions; these generators draw responses directly from the
generative models so the analysis can be checked against known truth quickly.
Defaults follow the paper's designs and reported effects.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd
from scipy.stats import norm

DETECTION_LEVELS_D = (0.0, 0.25, 0.5, 0.75, 1.0)
DISCRIMINATION_LEVELS_D = {1.0: (0.0, 0.45, 0.9, 1.35, 1.8), 2.0: (0.0, 0.45, 0.9, 1.35, 1.8), 3.0: (0.0, 0.7, 1.4, 2.1, 2.8)}
MODES = ("conventional", "ocular", "reversed")
ORDINAL_PC = {  # the paper's group means, (mode, separation_D) -> proportion correct
    ("conventional", 1.0): 0.488, ("conventional", 2.0): 0.526,
    ("ocular", 1.0): 0.667, ("ocular", 2.0): 0.758,
    ("reversed", 1.0): 0.604, ("reversed", 2.0): 0.674,
}
REACH_TARGETS = (0.50, 0.58, 0.67, 0.75, 0.82, 0.90)


def _participants(n: int) -> list[str]:
    return [f"{i + 1:02d}" for i in range(n)]


def pc_2afc(level_D: np.ndarray | float, threshold_D: float, sigma_D: float, lapse: float) -> np.ndarray:
    """2AFC proportion correct of a cumulative normal whose 75 % point (without lapse) is ``threshold_D``."""
    return 0.5 + (0.5 - lapse) * norm.cdf((np.asarray(level_D, float) - threshold_D) / sigma_D)


def true_t75(threshold_D: float, sigma_D: float, lapse: float) -> float:
    """The level where :func:`pc_2afc` reaches exactly 75 % correct (lapse included)."""
    return float(threshold_D + sigma_D * norm.ppf(0.25 / (0.5 - lapse)))


def simulate_2afc(
    rng: np.random.Generator, n_subjects: int, thresholds_D: Mapping[float, float],
    levels_D: Mapping[float, Sequence[float]], condition_column: str, n_per_level: int = 15,
    sigma_D: float = 0.2, lapse: float = 0.0, between_subject_sd_D: float = 0.0, study: str = "detection",
) -> pd.DataFrame:
    """Trial table of a 2AFC threshold study: one row per trial, ``correct`` drawn per trial."""
    rows = []
    for participant in _participants(n_subjects):
        shift = rng.normal(0.0, between_subject_sd_D) if between_subject_sd_D > 0 else 0.0
        for cond, threshold in thresholds_D.items():
            for level in levels_D[cond]:
                p = pc_2afc(level, threshold + shift, sigma_D, lapse)
                for correct in rng.random(n_per_level) < p:
                    rows.append({"study": study, "participant": participant, "session": 1,
                                 condition_column: float(cond), "level_D": float(level), "correct": bool(correct)})
    out = pd.DataFrame(rows)
    out["trial"] = out.groupby("participant").cumcount()
    return out


def simulate_detection(rng: np.random.Generator, n_subjects: int = 6, threshold_D: float = 0.36, **kw) -> pd.DataFrame:
    backs = (1.0, 2.0, 3.0)
    return simulate_2afc(rng, n_subjects, {b: threshold_D for b in backs}, {b: DETECTION_LEVELS_D for b in backs},
                         "back_D", study="detection", **kw)


def simulate_discrimination(rng: np.random.Generator, n_subjects: int = 6, intercept_D: float = 0.38,
                            slope: float = 0.11, **kw) -> pd.DataFrame:
    thresholds = {o: intercept_D + slope * o for o in DISCRIMINATION_LEVELS_D}
    return simulate_2afc(rng, n_subjects, thresholds, DISCRIMINATION_LEVELS_D, "offset_D", study="discrimination", **kw)


def simulate_ordinal(rng: np.random.Generator, n_subjects: int = 19, pc: Mapping[tuple[str, float], float] = ORDINAL_PC,
                     n_per_cell: int = 15, subject_sd: float = 0.08) -> pd.DataFrame:
    """Left/right-nearer trials; each subject's p(correct) = cell mean + a subject offset."""
    rows = []
    for participant in _participants(n_subjects):
        offset = rng.normal(0.0, subject_sd)
        for (mode, sep), p in pc.items():
            p_subject = float(np.clip(p + offset, 0.01, 0.99))
            for correct in rng.random(n_per_cell) < p_subject:
                rows.append({"study": "ordinal", "participant": participant, "session": 1, "mode": mode,
                             "separation_D": float(sep), "correct": bool(correct)})
    return pd.DataFrame(rows)


def simulate_reach(rng: np.random.Generator, n_subjects: int = 13,
                   lines: Mapping[str, tuple[float, float]] | None = None, noise_sd: float = 0.08,
                   n_repeats: int = 5, subject_sd: float = 0.05, slope_sd: float = 0.0,
                   max_reach_fraction: float | None = None, hand_height_m: float = -0.15) -> pd.DataFrame:
    """Blind-reach trials; reach fraction = intercept + slope * target fraction + a participant's
    own intercept (sd ``subject_sd``) and slope (sd ``slope_sd``) deviations + noise.

    ``lines`` maps rendering -> (slope, intercept) in fractions of arm reach; the paper
    reports 1.141/0.167 (enabled) and 1.128/0.165 (disabled). Reach and target are horizontal
    distances (psyop.session.reach); with ``max_reach_fraction`` the hand, ``hand_height_m``
    below the eyes, ends at most that fraction of arm reach from the eyes (as the session observer).
    """
    lines = lines or {"enabled": (1.141, 0.167), "disabled": (1.128, 0.165)}
    frames = []
    for participant in _participants(n_subjects):
        arm_m = rng.uniform(0.6, 0.8)
        bias = rng.normal(0.0, subject_sd) if subject_sd > 0 else 0.0
        slope_dev = rng.normal(0.0, slope_sd) if slope_sd > 0 else 0.0
        for rendering, (slope, intercept) in lines.items():
            target = np.repeat(np.asarray(REACH_TARGETS, float), n_repeats)
            reach = intercept + (slope + slope_dev) * target + bias + rng.normal(0.0, noise_sd, target.size)
            if max_reach_fraction is not None:
                top = np.sqrt(max(max_reach_fraction ** 2 - (hand_height_m / arm_m) ** 2, 0.0))
                reach = np.clip(reach, 0.0, top)
            frames.append(pd.DataFrame({"study": "egocentric", "participant": participant, "session": 1,
                                        "rendering": rendering, "target_fraction": target, "arm_reach_m": arm_m,
                                        "reach_m": reach * arm_m}))
    return pd.concat(frames, ignore_index=True)


def simulate_realism(rng: np.random.Generator, n_subjects: int = 19,
                     p_first: Mapping[tuple[str, str], float] | None = None, n_per_pair: int = 15) -> pd.DataFrame:
    """Pairwise-preference trials; ``p_first`` maps (first, second) -> P(first chosen)."""
    p_first = p_first or {("ocular", "conventional"): 0.768, ("reversed", "conventional"): 0.751,
                          ("ocular", "reversed"): 0.491}
    frames = []
    for participant in _participants(n_subjects):
        for (first, second), p in p_first.items():
            order = np.arange(n_per_pair) % 2 == 0
            chose_first = rng.random(n_per_pair) < p
            chosen = np.where(chose_first, first, second)
            frames.append(pd.DataFrame({
                "study": "realism", "participant": participant, "session": 1,
                "mode_a": np.where(order, first, second), "mode_b": np.where(order, second, first),
                "chosen_mode": chosen, "response": chosen}))
    out = pd.concat(frames, ignore_index=True)
    out["pair"] = out["mode_a"] + "|" + out["mode_b"]
    return out
