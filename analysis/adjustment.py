"""Method of adjustment (an ``adjustment`` study, protocols/examples/adjustment.yaml): the point of subjective
equality (PSE: the mean final setting), its bias from the reference (mean of final - reference) and the precision
(SD of final - reference, ddof 1) per participant and condition, their means across participants with 95 % t
intervals, and the repeated-measures ANOVA of the PSE over the condition factors (one or two, Greenhouse-Geisser;
with 2 or more conditions), all from psyop.statistics.adjustment. The final settings are the trials'
``response_value``; the references their ``<variable>_reference`` column (psyop/protocol/kinds/adjustment.py).
Timed-out trials are left out (psyop.statistics.dataset).

The SD of n settings underestimates sigma by c4(n) (psyop.statistics.adjustment.c4): the summary gives the mean SD
as it is and, beside it, divided by c4(n) per participant (``sd_unbiased``).

Writes results/<study>_adjustment.csv (one row per participant x condition), results/<study>_adjustment_summary.csv
(the means), results/<study>.json (the summary, the ANOVA) and figures/<study>_adjustment.png (the final settings
per condition with the reference and the mean PSEs; a few example paths).
"""

from __future__ import annotations

import json
import sys

import numpy as np
import pandas as pd
from _common import out_path, parser, provenance, require_columns, require_kind, results_file, run, write_csv, write_json

from psyop.statistics.studies import study_facts

#: the schedule column naming the adjusted variable (psyop/protocol/kinds/adjustment.py)
VARIABLE_COLUMN = "adjustment_variable"


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "figures/{study}_adjustment.png", study="depth_adjustment")
    args = p.parse_args(argv)
    from psyop.statistics.adjustment import c4, pse_by_participant, summary
    from psyop.statistics.dataset import load_dataset

    facts = study_facts(args.data, args.study)
    require_kind(facts, "adjustment", "adjustment.py")
    ds = load_dataset(args.data, args.study)
    trials = ds.trials
    where = str(args.data / args.study)
    require_columns(trials, ["participant", "response_value", VARIABLE_COLUMN], where,
                    "the trials of an adjustment session have them; re-run the session with this psyop")
    variable = str(trials[VARIABLE_COLUMN].dropna().iloc[0])
    reference = f"{variable}_reference"
    require_columns(trials, [reference], where, "the trials of an adjustment session have it")
    trials = trials.assign(final_value=pd.to_numeric(trials["response_value"]),
                           reference_value=pd.to_numeric(trials[reference]))
    conditions = [name for name in facts.factors if name in trials and trials[name].nunique() > 1]
    table = pse_by_participant(trials, conditions)
    table["sd_unbiased"] = [sd / c4(int(n)) if n >= 2 else np.nan for sd, n in zip(table["sd"], table["n"])]
    result = summary(table, conditions)
    means = result.table
    unbiased = table.groupby(conditions, observed=True, sort=True)["sd_unbiased"].mean() if conditions else \
        pd.Series({"all": table["sd_unbiased"].mean()})
    anova = result.anova
    args.results.mkdir(parents=True, exist_ok=True)
    write_csv(table, results_file(args.results, args.study, "adjustment", "csv"))
    write_csv(means, results_file(args.results, args.study, "adjustment_summary", "csv"))
    write_json(results_file(args.results, args.study), {
        **provenance(facts, "adjustment", args.pool_protocols), "simulated": ds.simulated, "conditions": conditions,
        "variable": variable, "ci_level": 0.95, "n_participants": int(trials["participant"].nunique()),
        "n_trials": len(trials),
        "summary": {_label(r, conditions): f"{r['mean']:.4f} [{r['ci_low']:.4f}, {r['ci_high']:.4f}] (n = {r['n']})"
                    + (f" ({r['flags']})" if r["flags"] else "") for r in means.to_dict("records")},
        "sd_unbiased_mean": {str(k): float(v) for k, v in unbiased.items()},
        "anova": None if anova is None else anova.table.to_dict("records"),
        "anova_dropped": None if anova is None else anova.dropped.to_dict("records"),
        "anova_note": result.anova_note,
    })
    _figure(trials, means, conditions, variable, args.study, ds.simulated, out_path(args))
    print(means.to_string(index=False))
    return 0


def _label(row: dict, conditions: list[str]) -> str:
    where = ", ".join(f"{c} = {row[c]}" for c in conditions)
    return f"{row['measure']}" + (f" ({where})" if where else "")


def _figure(trials, means, conditions, variable, study, simulated, out) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from psyop.figures.output import save_figure
    from psyop.figures.study_figures import mark_simulated

    cells = [dict(zip(conditions, key if isinstance(key, tuple) else (key,)))
             for key, _ in trials.groupby(conditions, observed=True, sort=True)] if conditions else [{}]
    fig, (left, right) = plt.subplots(1, 2, figsize=(11.0, 4.2))
    pse = means[means["measure"] == "pse"].reset_index(drop=True)
    rng = np.random.default_rng(0)  # horizontal jitter of the points only
    for i, cell in enumerate(cells):
        mask = np.ones(len(trials), dtype=bool)
        for c, v in cell.items():
            mask &= (trials[c] == v).to_numpy()
        finals = trials.loc[mask, "final_value"].to_numpy(float)
        left.plot(i + rng.uniform(-0.15, 0.15, finals.size), finals, ".", color="0.6", ms=3)
        ref = trials.loc[mask, "reference_value"].to_numpy(float)
        left.hlines(np.unique(ref), i - 0.35, i + 0.35, color="k", lw=1.2, label="reference" if i == 0 else None)
        if i < len(pse):
            row = pse.iloc[i]
            left.errorbar(i, row["mean"], yerr=[[row["mean"] - row["ci_low"]], [row["ci_high"] - row["mean"]]],
                          fmt="o", color="C0", capsize=3, label="mean PSE (95 % CI)" if i == 0 else None)
    left.set_xticks(range(len(cells)), [", ".join(str(v) for v in c.values()) or "all" for c in cells],
                    rotation=30 if len(cells) > 6 else 0)
    left.set_xlabel(", ".join(conditions) or "condition")
    left.set_ylabel(f"final setting ({variable})")
    left.legend(fontsize=8)
    path_column = f"{variable}_path"
    shown = 0
    if path_column in trials:
        for text in trials[path_column].dropna():
            try:
                path = np.asarray(json.loads(text), dtype=float)
            except (TypeError, ValueError):
                continue
            if path.ndim != 2 or len(path) < 2:
                continue
            right.step(path[:, 0], path[:, 1], where="post", lw=0.9)
            shown += 1
            if shown == 6:
                break
    right.set_xlabel("time from the response phase's start (s)")
    right.set_ylabel(variable)
    right.set_title(f"{shown} example paths", fontsize=9)
    fig.suptitle(f"Adjustment: {study}")
    mark_simulated(fig, simulated)
    save_figure(fig, out)


if __name__ == "__main__":
    sys.exit(run(main))
