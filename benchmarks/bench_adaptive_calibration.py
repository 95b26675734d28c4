"""Are the adaptive procedures' logged estimates and SDs calibrated? Coverage over simulated observers.

Held-out observers (not the procedures' own prior): 2AFC p = 0.5 + (0.5 - lapse) Phi((x - t) / w),
thresholds t ~ U(0.2, 1.0) D, widths w ~ U(0.1, 0.4) D, lapse ~ U(0, 0.05). For every observer and
checkpoint (trials so far) the procedure's logged estimate m and SD s are what ``state(history)``
reports; the interval m +- 1.96 s "covers" when it holds the observer's true threshold t (the 75 %
point without lapse, the quantity the analysis and the paper report). A calibrated procedure covers
in about 95 % of observers (binomial SE about 1 % at 500 observers).

Procedures: QUEST+ over 0-2 D (default grids, 0.02 D), and a 1-up-3-down staircase from 1 D, steps
0.2/0.1/0.05 D, range 0-2 D, whose estimate is (a) before this benchmark: the mean of its reversal
levels after the first two +- their standard error; (b) now (psyop.adaptive.staircase, "estimate"):
the posterior mean and SD of the threshold given its trials, on QUEST+'s default grid over [min, max].

Second table: a ``target_sd`` stop on the logged SD against fixed-length runs of the same procedure at
equal RMS error (the trials a calibrated stop saves).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from benchmarks.bench_adaptive import p_correct, posterior_stats, run_quest_plus
from psyop.adaptive import Observation, QuestPlus, QuestPlusSpec, Staircase, StaircaseSpec, StopRule

LEVEL_MIN_D, LEVEL_MAX_D = 0.0, 2.0
Z95 = 1.959963984540054


def held_out_observers(n: int, seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {"threshold": rng.uniform(0.2, 1.0, n), "width": rng.uniform(0.1, 0.4, n),
            "lapse": rng.uniform(0.0, 0.05, n)}


def reversal_estimates(levels: np.ndarray, correct: np.ndarray, checkpoints: np.ndarray,
                       spec: StaircaseSpec) -> tuple[np.ndarray, np.ndarray]:
    """The old staircase estimate: mean of the reversal levels after ``discard_reversals``, +- its SE."""
    n_obs = levels.shape[0]
    means = np.full((n_obs, checkpoints.size), np.nan)
    sds = np.full_like(means, np.inf)
    for i in range(n_obs):
        history = [Observation(float(x), bool(c)) for x, c in zip(levels[i], correct[i])]
        for j, n in enumerate(checkpoints):
            reversals = _reversal_levels(history[:n], spec)[spec.discard_reversals:]
            if len(reversals) >= 2:
                means[i, j] = float(np.mean(reversals))
                sds[i, j] = float(np.std(reversals, ddof=1) / math.sqrt(len(reversals)))
    return means, sds


def _reversal_levels(history: list[Observation], spec: StaircaseSpec) -> list[float]:
    """Reversal levels of a transformed staircase's history (the walk of psyop.adaptive.staircase)."""
    out: list[float] = []
    last = 0
    run_c = run_w = 0
    for obs in history:
        direction = 0
        if obs.correct:
            run_c, run_w = run_c + 1, 0
            if run_c >= spec.down:
                direction, run_c = -1, 0
        else:
            run_c, run_w = 0, run_w + 1
            if run_w >= spec.up:
                direction, run_w = 1, 0
        if direction:
            if last and direction != last:
                out.append(obs.level)
            last = direction
    return out


def run_staircase_trials(spec: StaircaseSpec, obs: dict[str, np.ndarray], n_trials: int,
                         rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Levels of the staircase's own walk (``Staircase.next_level``: its estimate does not move them)."""
    n = obs["threshold"].size
    stair = Staircase(spec)
    levels = np.empty((n, n_trials))
    correct = np.empty((n, n_trials), dtype=bool)
    draws = rng.random((n, n_trials))
    for i in range(n):
        one = {k: v[i] for k, v in obs.items()}
        level = float(spec.start)
        history: list[Observation] = []
        for k in range(n_trials):
            ok = bool(draws[i, k] < p_correct(np.asarray(level), one))
            history.append(Observation(level, ok))
            levels[i, k], correct[i, k] = level, ok
            level = stair.next_level(history)
    return levels, correct


def coverage(means: np.ndarray, sds: np.ndarray, truth: np.ndarray) -> tuple[float, int, float]:
    """(share of defined intervals covering the truth, defined intervals, mean SD / RMS error)."""
    defined = np.isfinite(sds)
    inside = np.abs(means[defined] - truth[defined]) <= Z95 * sds[defined]
    rms = float(np.sqrt(np.mean((means[defined] - truth[defined]) ** 2)))
    return float(inside.mean()) if defined.any() else math.nan, int(defined.sum()), float(np.mean(sds[defined])) / rms


TARGET_SD_D = 0.1


def stop_against_fixed(means: np.ndarray, sds: np.ndarray, truth: np.ndarray, checkpoints: np.ndarray) -> str:
    """A ``target_sd`` stop (each observer stops at the first checkpoint whose logged SD <= TARGET_SD_D, else at
    the last) against fixed-length runs: the fewest fixed trials whose RMS error is at most the stop's."""
    reached = sds <= TARGET_SD_D
    first = np.where(reached.any(axis=1), reached.argmax(axis=1), checkpoints.size - 1)
    trials = checkpoints[first]
    errors = means[np.arange(means.shape[0]), first] - truth
    rms_stop = float(np.sqrt(np.mean(errors ** 2)))
    rms_fixed = np.sqrt(np.mean((means - truth[:, None]) ** 2, axis=0))
    equal = np.flatnonzero(rms_fixed <= rms_stop)
    fixed = f"{int(checkpoints[equal[0]])}" if equal.size else f"not reached by {int(checkpoints[-1])}"
    saved = f"{int(checkpoints[equal[0]]) - trials.mean():+.1f}" if equal.size else "n/a"
    censored = int((~reached.any(axis=1)).sum())
    return (f"| {trials.mean():.1f} | {censored} | {rms_stop:.3f} | {fixed} | {saved} |")


def run(out_dir: Path, quick: bool = False) -> str:
    n_obs = 60 if quick else 500
    seed = 1919
    checkpoints = np.array([20, 40, 80]) if quick else np.array([20, 40, 80, 120])
    max_trials = int(checkpoints.max())
    obs = held_out_observers(n_obs, seed)
    rng = np.random.default_rng(seed + 1)
    start = time.perf_counter()
    q = QuestPlus(QuestPlusSpec.default(LEVEL_MIN_D, LEVEL_MAX_D, stop=StopRule(max_trials=max_trials)))
    qp_levels, qp_correct = run_quest_plus(q, obs, max_trials, rng)
    stair_spec = StaircaseSpec(start=1.0, min=LEVEL_MIN_D, max=LEVEL_MAX_D, up=1, down=3, step_sizes=(0.2, 0.1, 0.05),
                               stop_reversals=None, stop=StopRule(max_trials=max_trials))
    st_levels, st_correct = run_staircase_trials(stair_spec, obs, max_trials, rng)
    truth = obs["threshold"][:, None] * np.ones((1, checkpoints.size))
    rows = []
    qp_m, qp_s = posterior_stats(q, qp_levels, qp_correct, checkpoints)
    old_m, old_s = reversal_estimates(st_levels, st_correct, checkpoints, stair_spec)
    # the staircase's logged estimate, exactly as the session logs it: Staircase.state
    stair = Staircase(stair_spec)
    new_m = np.empty((n_obs, checkpoints.size))
    new_s = np.empty_like(new_m)
    for i in range(n_obs):
        history = [Observation(float(x), bool(c)) for x, c in zip(st_levels[i], st_correct[i])]
        for j, n in enumerate(checkpoints):
            state = stair.state(history[:n])
            new_m[i, j], new_s[i, j] = state.estimate_mean, state.estimate_sd
    # QUEST+'s batched posterior is QuestPlus.state's (bench_adaptive checks the batched levels)
    history = [Observation(float(x), bool(c)) for x, c in zip(qp_levels[0], qp_correct[0])]
    assert np.isclose(q.state(history[:checkpoints[0]]).estimate_sd, qp_s[0, 0])
    for name, m, s in (("QUEST+ (posterior)", qp_m, qp_s),
                       ("1-up-3-down, reversal mean +- SE (before)", old_m, old_s),
                       ("1-up-3-down, posterior (now logged)", new_m, new_s)):
        for j, n in enumerate(checkpoints):
            cov, defined, ratio = coverage(m[:, j], s[:, j], truth[:, j])
            bias = float(np.nanmean(m[:, j][np.isfinite(s[:, j])] - truth[:, j][np.isfinite(s[:, j])]))
            rows.append(f"| {name} | {n} | {defined} | {cov:.3f} | {bias:+.3f} | {ratio:.2f} |")
    # the target_sd stop on the logged (calibrated) SD against fixed-length runs at equal RMS error
    stops = np.arange(10, max_trials + 1, 10 if quick else 5)
    stop_rows = []
    qp_m2, qp_s2 = posterior_stats(q, qp_levels, qp_correct, stops)
    st_m2 = np.empty((n_obs, stops.size))
    st_s2 = np.empty_like(st_m2)
    for i in range(n_obs):
        history = [Observation(float(x), bool(c)) for x, c in zip(st_levels[i], st_correct[i])]
        for j, n in enumerate(stops):
            state = stair.state(history[:n])
            st_m2[i, j], st_s2[i, j] = state.estimate_mean, state.estimate_sd
    for name, m, s_ in (("QUEST+", qp_m2, qp_s2), ("1-up-3-down (posterior SD)", st_m2, st_s2)):
        stop_rows.append(f"| {name} " + stop_against_fixed(m, s_, obs["threshold"], stops))
    elapsed = time.perf_counter() - start
    lines = [
        "## Adaptive estimates: coverage of the true threshold by estimate +- 1.96 SD (bench_adaptive_calibration)",
        "",
        f"{n_obs} held-out simulated 2AFC observers (seed {seed}): thresholds U(0.2, 1.0) D, widths U(0.1, 0.4) D,",
        "lapse U(0, 0.05). Coverage: the share of observers whose true 75 % threshold lies within the logged",
        "estimate +- 1.96 x the logged SD (defined intervals only); bias: mean(estimate - truth);",
        "SD / error: mean logged SD over the RMS error (1 = the SD is the size of the real error).",
        "",
        "| procedure and estimate | trials | observers | coverage | bias (D) | SD / error |",
        "|---|---|---|---|---|---|",
        *rows,
        "",
        f"Stopping at target_sd {TARGET_SD_D:g} D on the logged SD (checked every {int(stops[1] - stops[0])} trials, "
        f"at most {max_trials}) against fixed-length runs of the same procedure: the fewest fixed trials whose RMS",
        "error across observers is at most the stop's (equal error), and the trials saved per observer.",
        "",
        "| procedure | mean trials with the stop | never reached the SD | RMS error (D) | fixed trials at equal error | "
        "saved per observer |",
        "|---|---|---|---|---|---|",
        *stop_rows,
        "",
        f"_{elapsed:.1f} s_",
    ]
    report = "\n".join(lines) + "\n"
    (out_dir / "bench_adaptive_calibration.md").write_text(report)
    return report
