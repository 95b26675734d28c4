"""Power of the discrimination study's slope at the paper's six participants: ``psyop power``
(whole simulated studies through compile -> session -> analysis) beside a plain re-simulation
(trial tables drawn directly from the same observer model by psyop.statistics.simulate, then the
same psignifit fits and linear fit). The two should agree within their binomial CIs."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from scipy.stats import binomtest

from psyop.power.run import PowerRun, run_power
from psyop.protocol import load_protocol

PROTOCOL = Path(__file__).resolve().parents[1] / "protocols" / "discrimination.yaml"


def plain_resimulation(replications: int, participants: int, seed: int) -> tuple[int, int]:
    """(significant, replications) of the slope test on trial tables drawn without sessions."""
    from psyop.statistics.psychometric import FitOptions, fit_psychometric_table, usable_for_analysis
    from psyop.statistics.regression import linear_fit
    from psyop.statistics.simulate import simulate_discrimination

    observer = load_protocol(PROTOCOL).observer
    rng = np.random.default_rng(seed)
    significant = 0
    for _ in range(replications):
        trials = simulate_discrimination(rng, participants, intercept_D=observer.threshold_D,
                                         slope=observer.threshold_slope, sigma_D=observer.width_D,
                                         lapse=observer.lapse, between_subject_sd_D=observer.between_subject_sd_D)
        fits = fit_psychometric_table(trials, "level_D", ["participant", "offset_D"], options=FitOptions())
        clean, _ = usable_for_analysis(fits)  # the documented status rule (censored etc. left out)
        significant += bool(linear_fit(clean, "offset_D", "threshold_D").slope_p < 0.05)
    return significant, replications


def _ci(k: int, n: int) -> str:
    ci = binomtest(k, n).proportion_ci(method="exact")
    return f"{k / n:.2f} [{ci.low:.2f}, {ci.high:.2f}]"


def run(out_dir: Path, quick: bool) -> str:
    replications = 20 if quick else 150
    start = time.perf_counter()
    table, _ = run_power(PowerRun(protocol_path=PROTOCOL, participants=(6,), replications=replications, seed=2020,
                                  jobs=2))
    t_power = time.perf_counter() - start
    start = time.perf_counter()
    k_plain, n_plain = plain_resimulation(replications, 6, seed=2020)
    t_plain = time.perf_counter() - start
    table.to_csv(out_dir / "power_discrimination_6.csv", index=False)
    lines = [
        "## Power by simulation: discrimination slope at six participants (bench_power)",
        "",
        f"{replications} simulated studies of protocols/discrimination.yaml (observer: intercept 0.38 D, slope 0.11,",
        "width 0.25 D, lapse 0.02, between-subject SD 0.05 D), alpha 0.05, 95 % Clopper-Pearson CIs.",
        "",
        "| path | test | power [95 % CI] |",
        "|---|---|---|",
    ]
    for _, r in table.iterrows():
        lines.append(f"| psyop power (compile -> session -> analysis) | {r['test']} | "
                     f"{_ci(int(r['n_significant']), int(r['n_replications']))} |")
    lines.append(f"| plain re-simulation (psyop.statistics.simulate + same fits) | regression slope | "
                 f"{_ci(k_plain, n_plain)} |")
    lines += ["", f"Time (context): psyop power {t_power:.0f} s on 2 processes, plain re-simulation {t_plain:.0f} s."]
    return "\n".join(lines)
