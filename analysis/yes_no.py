"""Yes/no detection (a ``yes_no`` study, protocols/examples/yes_no.yaml): hit and false-alarm rates, d' and
criterion c per participant and condition (log-linear correction on every cell, psyop.statistics.signal_detection),
their means across participants with 95 % t intervals, and, when the response has a level factor with two or
more levels, a psychometric fit of "yes" on the signal trials over the level per participant and condition,
with a free guess (false-alarm) rate (psyop.statistics.psychometric, psignifit's yes/no type).

Writes results/<study>_yes_no.csv (one row per participant x condition), results/<study>_yes_no_fits.csv (the
fits, when fitted), results/<study>.json (the summary) and figures/<study>_yes_no.png (d' by condition; the
proportion "yes" of signal and noise trials by level with the fitted curves).
"""

from __future__ import annotations

import sys

import numpy as np
from _common import out_path, parser, provenance, require_columns, require_kind, results_file, run, write_csv, write_json
from _confidence import confidence_analysis

from psyop.statistics.studies import study_facts


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "figures/{study}_yes_no.png", study="yes_no_detection")
    p.add_argument("--n-jobs", type=int, default=1, help="processes for the psychometric fits")
    args = p.parse_args(argv)
    from psyop.statistics.dataset import load_dataset
    from psyop.statistics.signal_detection import CORRECTION, rates, summary

    facts = study_facts(args.data, args.study)
    require_kind(facts, "yes_no", "yes_no.py")
    ds = load_dataset(args.data, args.study)
    trials = ds.trials
    require_columns(trials, ["participant", "signal", "response"], str(args.data / args.study),
                    "the trials of a yes_no session have them; re-run the session with this psyop")
    trials = trials.assign(answer_yes=trials["response"].astype(str) == "yes")
    conditions = [name for name in facts.factors if name in trials and trials[name].nunique() > 1]
    table = rates(trials, conditions)
    means = summary(table, conditions)
    level = facts.level_factor if facts.level_factor in conditions else None
    fits = _fits(trials, level, [c for c in conditions if c != level], args.n_jobs) if level else None
    args.results.mkdir(parents=True, exist_ok=True)
    write_csv(table, results_file(args.results, args.study, "yes_no", "csv"))
    if fits is not None:
        write_csv(fits, results_file(args.results, args.study, "yes_no_fits", "csv"))
    write_json(results_file(args.results, args.study), {
        **provenance(facts, "yes_no", args.pool_protocols), "simulated": ds.simulated, "conditions": conditions,
        "correction": CORRECTION, "level_factor": level, "ci_level": 0.95,
        "summary": {_label(r, conditions): f"{r['mean']:.3f} [{r['ci_low']:.3f}, {r['ci_high']:.3f}] (n = {r['n']})"
                    + (f" ({r['flags']})" if r["flags"] else "") for r in means.to_dict("records")},
        "fits_by_status": {} if fits is None else fits["status"].value_counts().to_dict(),
    })
    _figure(table, means, fits, trials, conditions, level, args.study, ds.simulated, out_path(args))
    confidence_analysis(trials, conditions, args.study, args.results, out_path(args), ds.simulated)  # if rated
    print(means.to_string(index=False))
    return 0


def _label(row: dict, conditions: list[str]) -> str:
    where = ", ".join(f"{c} = {row[c]}" for c in conditions)
    return f"{row['measure']}" + (f" ({where})" if where else "")


def _fits(trials, level: str, others: list[str], n_jobs: int):
    """p("yes") of the signal trials over ``level`` per participant x other condition, guess free."""
    from psyop.statistics.psychometric import fit_psychometric_table, yes_no_options

    signal = trials[trials["signal"].astype(bool)]
    return fit_psychometric_table(signal, level_column=level, group_columns=["participant", *others],
                                  correct_column="answer_yes", options=yes_no_options(None), n_jobs=n_jobs)


def _figure(table, means, fits, trials, conditions, level, study, simulated, out) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from psyop.figures.output import save_figure
    from psyop.figures.study_figures import mark_simulated

    fig, axes = plt.subplots(1, 2 if level else 1, figsize=(10.0 if level else 5.5, 4.0), squeeze=False)
    d = means[means["measure"] == "d_prime"].reset_index(drop=True)
    x = np.arange(len(d))
    ax = axes[0, 0]
    ax.errorbar(x, d["mean"], yerr=[d["mean"] - d["ci_low"], d["ci_high"] - d["mean"]], fmt="o", capsize=3)
    ax.set_xticks(x, [", ".join(str(r[c]) for c in conditions) or "all" for r in d.to_dict("records")],
                  rotation=30 if len(d) > 6 else 0)
    ax.set_xlabel(", ".join(conditions) or "condition")
    ax.set_ylabel("d' (mean, 95 % CI)")
    ax.axhline(0.0, color="0.6", lw=0.8)
    if level:
        ax = axes[0, 1]
        for signal, group in trials.groupby(trials["signal"].astype(bool)):
            share = group.groupby(level)["answer_yes"].mean()
            ax.plot(share.index, share.to_numpy(), "o-" if signal else "s--", label="signal" if signal else "noise")
        if fits is not None and len(fits):
            from psyop.statistics.psychometric import predicted_pc

            grid = np.linspace(float(trials[level].min()), float(trials[level].max()), 200)
            usable = fits[fits["status"].isin(["ok", "no_upper_bound"])]
            for row in usable.to_dict("records"):
                ax.plot(grid, predicted_pc(grid, row["location_D"], row["width_D"], row["lapse"], guess=row["guess"]),
                        color="0.5", lw=0.6, alpha=0.6)
        ax.set_xlabel(level)
        ax.set_ylabel('proportion "yes"')
        ax.set_ylim(-0.02, 1.02)
        ax.legend(fontsize=8, loc="upper left")
    fig.suptitle(f"Yes/no: {study}")
    mark_simulated(fig, simulated)
    save_figure(fig, out)


if __name__ == "__main__":
    sys.exit(run(main))
