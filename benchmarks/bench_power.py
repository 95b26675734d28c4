"""Power of the discrimination study's slope at the paper's six participants, three ways:

1. ``psyop power``: whole simulated studies through compile -> session -> analysis;
2. the direct re-simulation on identical seeds (psyop.power.direct: the same schedules and observer
   draws without sessions, the same study_tests): every replication's p value must equal path 1's
   exactly -- the benchmark fails otherwise;
3. an independent plain re-simulation: trial tables drawn by psyop.statistics.simulate from the
   protocol's observer parameters, then the same study_tests (same psignifit fits, same status
   rule: only fits with status ok/no_upper_bound enter, psyop.statistics.psychometric.
   usable_for_analysis; OLS slope of threshold on offset). Its power must agree with path 1's
   within chance (two-sided Fisher exact test on the two counts; reported).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from scipy.stats import binomtest, fisher_exact

from psyop.power.direct import run_direct_replication
from psyop.power.executors import run_local
from psyop.power.run import PowerRun, plan_tasks, run_power
from psyop.power.summary import power_table
from psyop.protocol import load_protocol

PROTOCOL = Path(__file__).resolve().parents[1] / "protocols" / "discrimination.yaml"
SLOPE_TEST = "regression slope: threshold ~ offset_D"


def plain_replication(task: tuple[int, int, int]) -> bool:
    """Is the slope significant in one trial table drawn without sessions (replication, participants,
    seed; seeded on its own like psyop power's replications)?"""
    from psyop.power.study_tests import study_tests
    from psyop.statistics.simulate import simulate_discrimination

    replication, participants, seed = task
    protocol = load_protocol(PROTOCOL)
    observer = protocol.observer
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(participants, replication)))
    trials = simulate_discrimination(rng, participants, intercept_D=observer.threshold_D,
                                     slope=observer.threshold_slope, sigma_D=observer.width_D,
                                     lapse=observer.lapse, between_subject_sd_D=observer.between_subject_sd_D)
    return bool({o.test: o for o in study_tests(protocol, trials)}[SLOPE_TEST].p < 0.05)


def plain_resimulation(replications: int, participants: int, seed: int, jobs: int = 1) -> tuple[int, int]:
    """(significant, replications) of the slope test on trial tables drawn without sessions."""
    tasks = [(r, participants, seed) for r in range(replications)]
    return sum(run_local(plain_replication, tasks, jobs)), replications


def _ci(k: int, n: int) -> str:
    ci = binomtest(k, n).proportion_ci(method="exact")
    return f"{k / n:.2f} [{ci.low:.2f}, {ci.high:.2f}]"


def run(out_dir: Path, quick: bool) -> str:
    replications = 3 if quick else 150
    jobs = 1 if quick else 2  # a spawned pool costs more than 3 replications
    run_spec = PowerRun(protocol_path=PROTOCOL, participants=(6,), replications=replications, seed=2020, jobs=jobs)
    start = time.perf_counter()
    table, results = run_power(run_spec)
    t_power = time.perf_counter() - start
    start = time.perf_counter()
    direct = run_local(run_direct_replication, plan_tasks(run_spec), jobs=jobs)
    t_direct = time.perf_counter() - start
    differing = [r.replication for r, d in zip(results, direct) if r.outcomes != d.outcomes]
    if differing:
        raise AssertionError(f"bench_power: the session path and the direct re-simulation on identical seeds give "
                             f"different p values in replications {differing}")
    start = time.perf_counter()
    k_plain, n_plain = plain_resimulation(replications, 6, seed=2020, jobs=jobs)
    t_plain = time.perf_counter() - start
    table.to_csv(out_dir / "power_discrimination_6.csv", index=False)
    slope = table[table["test"] == SLOPE_TEST].iloc[0]
    k_power, n_power = int(slope["n_significant"]), int(slope["n_replications"])
    fisher_p = fisher_exact([[k_power, n_power - k_power], [k_plain, n_plain - k_plain]]).pvalue
    direct_slope = power_table(direct)
    direct_slope = direct_slope[direct_slope["test"] == SLOPE_TEST].iloc[0]
    o = load_protocol(PROTOCOL).observer
    lines = [
        "## Power by simulation: discrimination slope at six participants (bench_power)",
        "",
        f"{replications} simulated studies per path of protocols/discrimination.yaml (observer: intercept "
        f"{o.threshold_D:g} D, slope {o.threshold_slope:g},",
        f"width {o.width_D:g} D, lapse {o.lapse:g}, between-subject SD {o.between_subject_sd_D:g} D), seed 2020, "
        "alpha 0.05, 95 % Clopper-Pearson CIs.",
        "Analysis rule in every path (psyop.power.study_tests): psignifit fit per participant x offset, fits whose",
        "status is not ok/no_upper_bound left out (usable_for_analysis, as analysis/fig_discrimination_thresholds.py),",
        "OLS slope of threshold on offset over the kept fits.",
        "",
        "| path | test | power [95 % CI] |",
        "|---|---|---|",
    ]
    for _, r in table.iterrows():
        lines.append(f"| psyop power (compile -> session -> analysis) | {r['test']} | "
                     f"{_ci(int(r['n_significant']), int(r['n_replications']))} |")
    lines.append(f"| direct re-simulation, identical seeds (psyop.power.direct) | {SLOPE_TEST} | "
                 f"{_ci(int(direct_slope['n_significant']), int(direct_slope['n_replications']))} |")
    lines.append(f"| independent plain re-simulation (psyop.statistics.simulate) | {SLOPE_TEST} | "
                 f"{_ci(k_plain, n_plain)} |")
    lines += [
        "",
        f"Paired check: all {replications} replications give identical p values for every test on the session path",
        f"and the direct path (the benchmark fails otherwise). psyop power vs the independent re-simulation: "
        f"Fisher exact p = {fisher_p:.2f}.",
        "",
        f"Time (context): psyop power {t_power:.0f} s on {jobs} process(es), direct {t_direct:.0f} s on {jobs}, "
        f"plain re-simulation {t_plain:.0f} s on {jobs}.",
    ]
    return "\n".join(lines)
