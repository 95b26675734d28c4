"""Efficiency of adaptive procedures against the paper's constant stimuli, and QUEST+ update cost.

Simulated 2AFC observers p = 0.5 + (0.5 - lapse) * Phi((x - t) / w) (psyop's observer model) with
thresholds t uniform in 0.1-1.5 D, widths w uniform in 0.1-0.5 D and lapse uniform in 0-0.04.
Three ways to place trials for one threshold:
- QUEST+ (psyop.adaptive.QuestPlus, default grids over 0-2 D, 0.02 D steps);
- a 1-up-3-down staircase from 1 D, steps 0.2/0.1/0.05 D after 0/1/2+ reversals, range 0-2 D;
- constant stimuli at the detection protocol's levels (protocols/detection.yaml: 0, 0.25, 0.5,
  0.75, 1 D), in random order; the paper spent 75 trials per threshold (225 for three).
Every method's trials go through the same estimator, so only the placement differs: the posterior
mean of the threshold on QUEST+'s default grid (uniform prior over threshold x width x lapse).
At each checkpoint (trials per threshold) the error e = estimate - true threshold over all observers
gives bias = mean(e) and SD = sd(e); "trials needed" is the first checkpoint with SD <= 0.05 D and
|bias| < 0.02 D, or "not reached by N" (never a silent extrapolation).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from scipy.special import ndtr

from psyop.adaptive import Observation, QuestPlus, QuestPlusSpec, Staircase, StaircaseSpec, StopRule
from psyop.protocol import load_protocol

PROTOCOLS = Path(__file__).resolve().parents[1] / "protocols"
TARGET_SD_D = 0.05
MAX_BIAS_D = 0.02
LEVEL_MIN_D, LEVEL_MAX_D = 0.0, 2.0


def detection_levels() -> np.ndarray:
    protocol = load_protocol(PROTOCOLS / "detection.yaml")
    levels = protocol.design.factors["level_D"].levels
    return np.asarray(levels, dtype=float)


def observers(n: int, seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {"threshold": rng.uniform(0.1, 1.5, n), "width": rng.uniform(0.1, 0.5, n),
            "lapse": rng.uniform(0.0, 0.04, n)}


def p_correct(level: np.ndarray, obs: dict[str, np.ndarray]) -> np.ndarray:
    return 0.5 + (0.5 - obs["lapse"]) * ndtr((level - obs["threshold"]) / obs["width"])


def run_quest_plus(q: QuestPlus, obs: dict[str, np.ndarray], n_trials: int, rng: np.random.Generator):
    """All observers side by side: (n_obs, n_trials) levels and responses. Same arithmetic as
    QuestPlus.state (checked against it for the first observers in run())."""
    n = obs["threshold"].size
    stim = np.asarray(q.spec.stimulus)
    log_post = np.tile(q.log_prior, (n, 1))
    levels = np.empty((n, n_trials))
    correct = np.empty((n, n_trials), dtype=bool)
    for k in range(n_trials):
        post = np.exp(log_post - log_post.max(axis=1, keepdims=True))
        post /= post.sum(axis=1, keepdims=True)
        index = np.argmin(q.expected_entropy_batch(post), axis=1)
        levels[:, k] = stim[index]
        correct[:, k] = rng.random(n) < p_correct(levels[:, k], obs)
        log_post += q.log_likelihood(index, correct[:, k])
    return levels, correct


def run_staircase(spec: StaircaseSpec, obs: dict[str, np.ndarray], n_trials: int, rng: np.random.Generator):
    n = obs["threshold"].size
    stair = Staircase(spec)
    levels = np.empty((n, n_trials))
    correct = np.empty((n, n_trials), dtype=bool)
    draws = rng.random((n, n_trials))
    for i in range(n):
        history: list[Observation] = []
        one = {k: v[i] for k, v in obs.items()}
        for k in range(n_trials):
            level = stair.state(history).next_level
            ok = bool(draws[i, k] < p_correct(np.asarray(level), one))
            history.append(Observation(level, ok))
            levels[i, k], correct[i, k] = level, ok
    return levels, correct


def run_constant(levels_D: np.ndarray, obs: dict[str, np.ndarray], n_trials: int, rng: np.random.Generator):
    n = obs["threshold"].size
    reps = -(-n_trials // levels_D.size)
    levels = np.stack([rng.permutation(np.repeat(levels_D, reps))[:n_trials] for _ in range(n)])
    correct = rng.random((n, n_trials)) < p_correct(levels, {k: v[:, None] for k, v in obs.items()})
    return levels, correct


def posterior_stats(estimator: QuestPlus, levels: np.ndarray, correct: np.ndarray,
                    checkpoints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Posterior mean and SD of the threshold after the first n trials, for every observer and
    checkpoint n: two (n_obs, n_checkpoints) arrays. Same posterior as QuestPlus.state (the
    estimator's grid holds every level shown; checked in run())."""
    stim = np.asarray(estimator.spec.stimulus)
    S = stim.size
    step = stim[1] - stim[0]
    index = np.rint((levels - stim[0]) / step).astype(int)
    if not np.allclose(stim[np.clip(index, 0, S - 1)], levels, atol=1e-9):
        raise ValueError("a level is off the estimator's grid")
    table = np.vstack([estimator.log_likelihood(np.arange(S), np.ones(S, bool)),
                       estimator.log_likelihood(np.arange(S), np.zeros(S, bool))])
    thresholds = np.asarray(estimator.spec.threshold)
    n_obs = levels.shape[0]
    means = np.empty((n_obs, checkpoints.size))
    sds = np.empty_like(means)
    for i in range(n_obs):
        onehot = np.zeros((levels.shape[1], 2 * S))
        onehot[np.arange(levels.shape[1]), index[i] + S * (~correct[i])] = 1.0
        counts = np.cumsum(onehot, axis=0)[checkpoints - 1]
        log_post = estimator.log_prior + counts @ table
        post = np.exp(log_post - log_post.max(axis=1, keepdims=True))
        marginal = post.reshape(checkpoints.size, *estimator.parameter_shape).sum(axis=(2, 3))
        marginal /= marginal.sum(axis=1, keepdims=True)
        means[i] = marginal @ thresholds
        sds[i] = np.sqrt(np.maximum(marginal @ thresholds ** 2 - means[i] ** 2, 0.0))
    return means, sds


def trials_needed(errors: np.ndarray, checkpoints: np.ndarray) -> tuple[int | None, list[tuple[float, float]]]:
    """First checkpoint where the error across observers has SD <= target and |bias| < bar."""
    stats = [(float(np.mean(errors[:, j])), float(np.std(errors[:, j], ddof=1))) for j in range(len(checkpoints))]
    for n, (bias, sd) in zip(checkpoints, stats):
        if sd <= TARGET_SD_D and abs(bias) < MAX_BIAS_D:
            return int(n), stats
    return None, stats


def per_observer_stop(means: np.ndarray, sds: np.ndarray, truth: np.ndarray, checkpoints: np.ndarray) -> dict:
    """Each observer stops at the first checkpoint whose posterior SD <= target (censored at the
    last checkpoint if never)."""
    reached = sds <= TARGET_SD_D
    any_reached = reached.any(axis=1)
    first = np.where(any_reached, reached.argmax(axis=1), checkpoints.size - 1)
    trials = checkpoints[first]
    errors = means[np.arange(means.shape[0]), first] - truth
    censored = np.where(any_reached, trials, np.inf)
    return {"median": float(np.percentile(censored, 50, method="higher")),
            "p90": float(np.percentile(censored, 90, method="higher")), "censored": int((~any_reached).sum()), "n": int(trials.size),
        "bias": float(errors[any_reached].mean()) if any_reached.any() else float("nan"),
        "error_sd": float(errors[any_reached].std(ddof=1)) if any_reached.sum() > 1 else float("nan")}


def update_cost_ms(n_observers: int, n_trials: int, seed: int, package_trials: int = 40) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-trial cost of the session's path (rebuild from history + next level) for psyop's QUEST+
    (wall and this thread's CPU time: on a shared machine the wall-time tail is mostly waiting for
    a core), and of the questplus package's next_stim + update on the same grids (wall; empty if
    the package is not installed)."""
    spec = QuestPlusSpec.default(LEVEL_MIN_D, LEVEL_MAX_D)
    q = QuestPlus(spec)
    obs = observers(n_observers, seed)
    rng = np.random.default_rng(seed)
    ours, ours_cpu = [], []
    for i in range(n_observers):
        one = {k: v[i] for k, v in obs.items()}
        history: list[Observation] = []
        for _ in range(n_trials):
            start, start_cpu = time.perf_counter(), time.thread_time()
            level = q.state(history).next_level
            ours_cpu.append(time.thread_time() - start_cpu)
            ours.append(time.perf_counter() - start)
            history.append(Observation(level, bool(rng.random() < p_correct(np.asarray(level), one))))
    theirs = []
    try:
        import questplus
    except ImportError:
        return np.asarray(ours) * 1e3, np.asarray(ours_cpu) * 1e3, np.asarray([])
    package = questplus.QuestPlus(
        stim_domain={"intensity": np.asarray(spec.stimulus)},
        param_domain={"mean": np.asarray(spec.threshold), "sd": np.asarray(spec.width), "lower_asymptote": 0.5,
                      "lapse_rate": np.asarray(spec.lapse)},
        outcome_domain={"response": ["Correct", "Incorrect"]}, func="norm_cdf", stim_scale="linear")
    one = {k: v[0] for k, v in obs.items()}
    for _ in range(min(n_trials, package_trials)):
        start = time.perf_counter()
        level = package.next_stim["intensity"]
        ok = bool(rng.random() < p_correct(np.asarray(level), one))
        package.update(stim={"intensity": level}, outcome={"response": "Correct" if ok else "Incorrect"})
        theirs.append(time.perf_counter() - start)
    return np.asarray(ours) * 1e3, np.asarray(ours_cpu) * 1e3, np.asarray(theirs) * 1e3


def _fmt_trials(value: float, last: int) -> str:
    return f"> {last} (not reached)" if not np.isfinite(value) else f"{value:.0f}"


def _ratio(value: float, reference: float, last_reference: int) -> str:
    if not np.isfinite(value):
        return "-"
    if not np.isfinite(reference):
        return f"< {value / last_reference:.2f} (constant stimuli > {last_reference})"
    return f"{value / reference:.2f}"


def run(out_dir: Path, quick: bool) -> str:
    # full size: the issue's >= 500 observers, and 400 adaptive trials because QUEST+ needs them to
    # reach the across-observer target (docs/adaptive.md); --quick is a smoke run of every table
    n_obs = 20 if quick else 500
    seed = 20201
    obs = observers(n_obs, seed)
    max_adaptive, max_constant = (60, 225) if quick else (400, 450)
    adaptive_cps = np.arange(5, max_adaptive + 1, 5)
    constant_cps = np.arange(5, max_constant + 1, 5)
    qp_spec = QuestPlusSpec.default(LEVEL_MIN_D, LEVEL_MAX_D)
    q = QuestPlus(qp_spec)
    estimator = QuestPlus(QuestPlusSpec.default(LEVEL_MIN_D, LEVEL_MAX_D, stimulus_count=201))
    stair_spec = StaircaseSpec(start=1.0, min=LEVEL_MIN_D, max=LEVEL_MAX_D, up=1, down=3, step_sizes=(0.2, 0.1, 0.05),
                               stop_reversals=None, stop=StopRule(max_trials=10_000))
    rng = np.random.default_rng([seed, 1])
    timings = {}
    start = time.perf_counter()
    qp_levels, qp_correct = run_quest_plus(q, obs, max_adaptive, rng)
    timings["QUEST+"] = time.perf_counter() - start
    # the batched simulation is the session's QuestPlus.state: same levels for the first observers
    for i in range(3):
        history = [Observation(float(x), bool(c)) for x, c in zip(qp_levels[i, :30], qp_correct[i, :30])]
        for k in range(30):
            assert q.state(history[:k]).next_level == qp_levels[i, k], (i, k)
    start = time.perf_counter()
    st_levels, st_correct = run_staircase(stair_spec, obs, max_adaptive, rng)
    timings["1-up-3-down"] = time.perf_counter() - start
    cs_levels, cs_correct = run_constant(detection_levels(), obs, max_constant, rng)
    truth = obs["threshold"]
    inside = truth <= 0.9
    start = time.perf_counter()
    results = []
    for name, lv, co, cps in (("QUEST+", qp_levels, qp_correct, adaptive_cps),
                               ("1-up-3-down staircase", st_levels, st_correct, adaptive_cps),
                               ("constant stimuli (detection levels)", cs_levels, cs_correct, constant_cps)):
        means, sds = posterior_stats(estimator, lv, co, cps)
        results.append({"name": name, "cps": cps, "stop_all": per_observer_stop(means, sds, truth, cps),
                        "stop_inside": per_observer_stop(means[inside], sds[inside], truth[inside], cps),
                        "across": trials_needed(means - truth[:, None], cps),
                        "across_inside": trials_needed(means[inside] - truth[inside, None], cps)})
    timings["estimates"] = time.perf_counter() - start
    # the vectorised estimator is QuestPlus.state's posterior
    check = [Observation(float(x), bool(c)) for x, c in zip(st_levels[0, :50], st_correct[0, :50])]
    m, sd = posterior_stats(estimator, st_levels[:1], st_correct[:1], np.array([50]))
    assert np.isclose(m[0, 0], estimator.state(check).estimate_mean) and np.isclose(sd[0, 0], estimator.state(check).estimate_sd)

    cs = results[2]
    lines = [
        "## Adaptive procedures: trials to a threshold SD of 0.05 D (bench_adaptive)",
        "",
        f"{n_obs} simulated 2AFC observers (seed {seed}): thresholds U(0.1, 1.5) D, widths U(0.1, 0.5) D, lapse",
        "U(0, 0.04); one threshold each. Every method's trials are scored by the same estimator (posterior",
        "mean/SD of the threshold on QUEST+'s default grid over 0-2 D), so only trial placement differs.",
        "Constant stimuli use the detection protocol's levels (0, 0.25, ..., 1 D); the paper spent 75 trials",
        f"per threshold (225 for its three back distances). 'inside': the {int(inside.sum())} observers with",
        "thresholds <= 0.9 D, which the constant-stimulus levels bracket.",
        "",
        f"**Per observer**: trials until the threshold's posterior SD <= {TARGET_SD_D} D (checked every 5 trials;",
        "'not reached': more than half (p90: a tenth) of the observers never got there); bias and SD of the error",
        "(estimate - true threshold) at that point, over the observers who got there.",
        "",
        "| method | observers | median trials | ratio to constant | p90 trials | not reached | bias (D) | error SD (D) |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for key, label in (("stop_all", "all"), ("stop_inside", "inside")):
        ref = cs[key]
        for r in results:
            st = r[key]
            last = int(r["cps"][-1])
            lines.append(f"| {r['name']} | {label} ({st['n']}) | {_fmt_trials(st['median'], last)} | "
                         f"{_ratio(st['median'], ref['median'], int(cs['cps'][-1]))} | {_fmt_trials(st['p90'], last)} | "
                         f"{st['censored']} | {st['bias']:+.3f} | {st['error_sd']:.3f} |")
    lines += [
        "",
        f"**Across observers**: first trial count at which the error over observers has SD <= {TARGET_SD_D} D and",
        f"|bias| < {MAX_BIAS_D} D (the widest observers dominate: at w = 0.5 D this needs a few hundred trials).",
        "",
        "| method | all: trials | ratio to constant | inside: trials | ratio to constant |",
        "|---|---:|---:|---:|---:|",
    ]
    for r in results:
        last = int(r["cps"][-1])
        n_all = float(r["across"][0]) if r["across"][0] is not None else np.inf
        n_in = float(r["across_inside"][0]) if r["across_inside"][0] is not None else np.inf
        ref_all = float(cs["across"][0]) if cs["across"][0] is not None else np.inf
        ref_in = float(cs["across_inside"][0]) if cs["across_inside"][0] is not None else np.inf
        lines.append(f"| {r['name']} | {_fmt_trials(n_all, last)} | {_ratio(n_all, ref_all, int(cs['cps'][-1]))} | "
                     f"{_fmt_trials(n_in, last)} | {_ratio(n_in, ref_in, int(cs['cps'][-1]))} |")
    lines += [
        "",
        "**Matching the paper's precision**: trials each method needs for the error SD across all observers",
        "that constant stimuli reach with 75 trials (the paper's budget per threshold) and with 225 (its",
        "budget per participant), |bias| < 0.02 D (first 5-trial checkpoint).",
        "",
        "| method | trials for constant stimuli's SD at 75 | ratio | trials for constant stimuli's SD at 225 | ratio |",
        "|---|---:|---:|---:|---:|",
    ]
    cs_stats = dict(zip(cs["cps"].tolist(), cs["across"][1]))
    for r in results:
        cells = []
        for budget in (75, 225):
            sd_target = cs_stats[budget][1]
            needed = next((int(c) for c, (b, sd) in zip(r["cps"], r["across"][1])
                           if sd <= sd_target and abs(b) < MAX_BIAS_D), None)
            cells += ([f"{needed}", f"{needed / budget:.2f}"] if needed is not None
                      else [f"> {int(r['cps'][-1])} (not reached)", "-"])
        lines.append(f"| {r['name']} | " + " | ".join(cells) + " |")
    shown = [25, 50, 75, 100, 150, 200, 225] + ([] if quick else [300, 400])
    lines += ["", "Bias / SD of the threshold error (D) by trials per threshold, all observers:", "",
              "| method | " + " | ".join(str(c) for c in shown) + " |", "|---|" + "---:|" * len(shown)]
    for r in results:
        stats = r["across"][1]
        cps = list(r["cps"])
        cells = [f"{stats[cps.index(c)][0]:+.3f} / {stats[cps.index(c)][1]:.3f}" if c in cps else "" for c in shown]
        lines.append(f"| {r['name']} | " + " | ".join(cells) + " |")
    ours, ours_cpu, theirs = update_cost_ms(3 if quick else 20, 30 if quick else 150, seed, 5 if quick else 40)
    lines += [
        "",
        "QUEST+ per-trial cost on the session's path (rebuild the posterior from the logged history, then",
        f"choose the next level; default grids: {len(qp_spec.stimulus)} levels x {len(qp_spec.threshold)} thresholds x "
        f"{len(qp_spec.width)} widths x {len(qp_spec.lapse)} lapses), {ours.size} trials, on a machine other jobs share:",
        "",
        "| implementation | p50 | p99 | max |",
        "|---|---:|---:|---:|",
        f"| psyop.adaptive.QuestPlus (history -> next level), wall | {np.percentile(ours, 50):.2f} ms | "
        f"{np.percentile(ours, 99):.2f} ms | {ours.max():.2f} ms |",
        f"| psyop.adaptive.QuestPlus (history -> next level), thread CPU | {np.percentile(ours_cpu, 50):.2f} ms | "
        f"{np.percentile(ours_cpu, 99):.2f} ms | {ours_cpu.max():.2f} ms |",
    ]
    if theirs.size:
        lines.append(f"| questplus package (next_stim + one update, no rebuild; {theirs.size} trials) | "
                     f"{np.percentile(theirs, 50):.2f} ms | {np.percentile(theirs, 99):.2f} ms | {theirs.max():.2f} ms |")
        lines += ["", f"Ratio of medians (package / psyop): {np.median(theirs) / np.median(ours):.1f}x. "
                      "Bar: p99 < 20 ms per trial."]
    lines += ["", "Simulation time (context): " + ", ".join(f"{k} {v:.1f} s" for k, v in timings.items()) + "."]
    return "\n".join(lines)
