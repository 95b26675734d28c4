"""results/summary.md in the paper's form, beside the paper: every statistic the paper reports with
the paper's value, psyop's value and whether the conclusion agrees (analysis/paper_values.py);
then each study's full statistics. Also results/summary.json.

Reads results/{detection_thresholds,discrimination_fit,ordinal,egocentric,realism}.json.
    python analysis/results_table.py --results results --out results/summary.md
"""

from __future__ import annotations

import json
import sys

from _common import parser, run, write_json, write_text
from paper_values import rows_for

STUDY_FILES = ["detection_thresholds", "discrimination_fit", "ordinal", "egocentric", "realism"]
#: The paper, cited by its reference (never by a path on the machine that built the summary).
PAPER_REFERENCE = ("Konrad, Angelopoulos and Wetzstein, \"Gaze-Contingent Ocular Parallax Rendering for Virtual "
                   "Reality\", ACM Transactions on Graphics, 2020 (sec. 5-6 and supplement)")


def _methods(studies: dict) -> list[str]:
    lines = ["## How psyop computed these", ""]
    lines.append("- Psychometric fits (detection, discrimination): psignifit 4.3 priors and grid, 2AFC cumulative "
                 "normal on linear D; threshold = 75 %-correct point of the MAP curve. **Eta (overdispersion) is "
                 "fixed at 0** for the threshold and its CI (psignifit's default integrates over eta; with it the "
                 "95 % intervals covered the truth in 100 % of simulated observers). Eta is still estimated per fit "
                 "(the `eta` column of results/*_fits.csv) and overdispersion is tested by the deviance bootstrap.")
    for name in ("detection_thresholds", "discrimination_fit"):
        s = studies.get(name)
        if s is not None:
            left = s.get("left_out_by_status") or {}
            lines.append(f"- {s['study']}: {s.get('n_left_out', 0)} of {s.get('n_fits', '?')} fits left out of the "
                         f"statistics by status ({left or 'none'}): censored thresholds are bounds, not numbers "
                         "(docs/statistics.md, 'Fit status').")
    o = studies.get("ordinal")
    if o is not None:
        lines.append(f"- Ordinal post-hoc: paired t-tests, Bonferroni over {o.get('bonferroni_family_text', '?')}; "
                     "set with `analysis/fig_ordinal_depth.py --bonferroni-family per_level|all`.")
    e = studies.get("egocentric")
    if e is not None:
        lines.append("- Egocentric: reach and target along the horizontal eye-to-target direction (as the supplement), as "
                     "fractions of arm reach. Primary test: linear mixed model with a random intercept and slope per "
                     "participant; the paper's pooled multiple regression (every reach independent) beside it.")
    lines.append("")
    return lines


def main(argv: list[str] | None = None) -> int:
    args = parser(__doc__, "results/summary.md").parse_args(argv)
    studies, simulated = {}, False
    for name in STUDY_FILES:
        path = args.results / f"{name}.json"
        if path.exists():
            studies[name] = json.loads(path.read_text())
            simulated |= bool(studies[name].get("simulated"))
    if not studies:
        print(f"no study results in {args.results}", file=sys.stderr)
        return 1
    rows = rows_for(studies)
    lines = ["# Statistics summary, beside the paper", ""]
    if simulated:
        lines += ["**Simulated data**: psyop's numbers come from simulated sessions, not participants; agreement "
                  "shows the analysis reproduces the paper's conclusions from data generated to resemble it.", ""]
    agree = sum(r["agrees"] == "yes" for r in rows)
    judged = sum(r["agrees"] != "n/a" for r in rows)
    lines += [f"Paper: {PAPER_REFERENCE}. Conclusions agree for {agree} of {judged} statistics judged "
              "(alpha 0.05 after the same correction; a value agrees when it lies in psyop's 95 % CI).", "",
              "| study | statistic | paper | psyop | conclusion agrees |", "|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['study'].split('_')[0]} | {r['statistic']} | {r['paper']} | {r['psyop']} | {r['agrees']} |")
    lines.append("")
    lines += _methods(studies)
    lines += ["## Every statistic psyop computed", ""]
    for name, payload in studies.items():
        lines += [f"### {payload.get('study', name)} (n = {payload.get('n_subjects', '?')})", ""]
        lines += [f"- {k}: {v}" for k, v in payload.get("summary", {}).items()]
        for key in ("left_out", "dropped"):
            if payload.get(key):
                lines.append(f"- {key}: " + "; ".join(json.dumps(x, sort_keys=True) for x in payload[key]))
        lines.append("")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_text(args.out, "\n".join(lines) + "\n")
    write_json(args.out.with_suffix(".json"), {
        "simulated": simulated, "paper_comparison": rows,
        "summary": {n: s.get("summary", {}) for n, s in studies.items()}, "studies": studies,
    })
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
