"""Egocentric reaching: how often re-simulations of the study find a condition difference.

The simulated observer's parameters come from protocols/egocentric.yaml (the observer block,
converted to fractions of arm reach). Each re-simulation: 13 participants x 6 targets x 5
repeats x 2 conditions, reaches bounded as the session observer bounds them. Reported: the
rejection rate (alpha 0.05) of the subject-aware primary test (MixedLM, random intercept and
slope per participant; joint Wald test of intercept and slope differences) and of the pooled
regression, with exact binomial 95 % intervals; and the same with the paper's two reported
lines taken as the true lines (why the observer uses their mean).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml
from scipy.stats import binomtest

from psyop.statistics.regression import condition_interaction, mixed_condition_comparison
from psyop.statistics.simulate import simulate_reach

PROTOCOL = Path(__file__).resolve().parents[1] / "protocols" / "egocentric.yaml"
PAPER_LINES = {"enabled": (1.141, 0.167), "disabled": (1.128, 0.165)}


def _rate(hits) -> str:
    hits = np.asarray(hits, bool)
    ci = binomtest(int(hits.sum()), hits.size).proportion_ci()
    return f"{hits.mean():.3f} [{ci.low:.3f}, {ci.high:.3f}]"


def observer_params() -> dict:
    obs = yaml.safe_load(PROTOCOL.read_text())["observer"]
    arm = float(obs["arm_reach_m"])
    conds = obs["by_condition"]
    return {
        "lines": {k: (float(v["slope"]), float(v["intercept_m"]) / arm) for k, v in conds.items()},
        "noise_sd": float(next(iter(conds.values()))["noise_sd_m"]) / arm,
        "subject_sd": float(obs.get("intercept_sd_m", 0.0)) / arm,
        "slope_sd": float(obs.get("slope_sd", 0.0)),
        "max_reach_fraction": float(obs.get("max_reach_fraction", 1.0)),
    }


def _rates(rng, params: dict, n: int) -> tuple[str, str, str, float]:
    mixed, pooled, fallbacks, slopes = [], [], 0, []
    for _ in range(n):
        d = simulate_reach(rng, **params)
        d["reach_fraction"] = d["reach_m"] / d["arm_reach_m"]
        m = mixed_condition_comparison(d, "target_fraction", "reach_fraction", "rendering", reference="disabled")
        c = condition_interaction(d, "target_fraction", "reach_fraction", "rendering", "disabled")
        mixed.append(m.joint_p < 0.05)
        pooled.append(c.joint_p < 0.05)
        fallbacks += bool(m.fallback_reason)
        slopes.append(m.slope)
    return _rate(mixed), _rate(pooled), f"{fallbacks}/{n}", float(np.mean(slopes))


def run(out_dir: Path, quick: bool) -> str:
    rng = np.random.default_rng(606)
    params = observer_params()
    n = 60 if quick else 300
    lines = ["## statistics: egocentric reaching, condition difference over re-simulations", "",
             f"Observer from `{PROTOCOL.name}`: lines {params['lines']} (slope, intercept as a fraction of arm reach), "
             f"trial noise sd {params['noise_sd']:.3f}, participant intercept sd {params['subject_sd']:.3f} and slope sd "
             f"{params['slope_sd']:.2f}, reaches bounded at {params['max_reach_fraction']:g} x arm reach (3-D).", "",
             "| true lines | re-simulations | MixedLM joint test rejects | pooled OLS joint F rejects | MixedLM fallbacks | mean fitted slope |",
             "|---|---|---|---|---|---|"]
    for name, lines_ in (("protocol observer (both conditions the mean of the paper's lines)", params["lines"]),
                         ("the paper's two reported lines", PAPER_LINES)):
        mixed, pooled, fb, slope = _rates(rng, dict(params, lines=lines_), n if lines_ is params["lines"] else n // 3)
        lines.append(f"| {name} | {n if lines_ is params['lines'] else n // 3} | {mixed} | {pooled} | {fb} | {slope:.3f} |")
    lines += ["", "The paper found no significant difference; with the protocol observer a re-simulated study finds "
              "none in 1 - (MixedLM rejection rate) of re-simulations."]
    return "\n".join(lines)
