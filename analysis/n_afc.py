"""n-alternative forced choice (an ``n_afc`` study, protocols/examples/n_afc.yaml): a psychometric function per
participant and condition with guess rate 1/n (psyop.statistics.psychometric, psignifit's nAFC type; the
threshold is the level where the proportion correct is halfway between 1/n and 1), and the usable thresholds'
mean per condition with a 95 % t interval (fits of other statuses are counted, never averaged).

Writes results/<study>_n_afc_fits.csv (one row per participant x condition), results/<study>.json (the summary)
and figures/<study>_n_afc.png (proportion correct by level with each participant's fitted curve; thresholds by
condition). The fits' level-valued columns carry the level factor's unit (psyop.statistics.level_units:
``threshold_fraction`` for a ``contrast_fraction`` level, ``threshold_D`` for ``level_D``).
"""

from __future__ import annotations

import sys

import numpy as np
from _common import out_path, parser, provenance, require_columns, require_kind, results_file, run, write_csv, write_json
from _confidence import confidence_analysis

from psyop.statistics.studies import study_facts


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "figures/{study}_n_afc.png", study="nafc_detection")
    p.add_argument("--n-jobs", type=int, default=1, help="processes for the psychometric fits")
    args = p.parse_args(argv)
    from psyop.errors import UserError
    from psyop.statistics.dataset import load_dataset
    from psyop.statistics.level_units import in_level_units, level_suffix, level_unit_text
    from psyop.statistics.psychometric import USABLE_STATUSES, fit_psychometric_table, nafc_options
    from psyop.statistics.signal_detection import t_summary

    facts = study_facts(args.data, args.study)
    require_kind(facts, "n_afc", "n_afc.py")
    ds = load_dataset(args.data, args.study)
    trials = ds.trials
    level = facts.level_factor
    require_columns(trials, ["participant", "correct", "n_alternatives", *([level] if level else [])],
                    str(args.data / args.study), "an n_afc study with a level_factor has them")
    if level is None:
        raise UserError("an n_afc study without a level_factor has no psychometric function to fit; give the response "
                        "a level_factor (or analyse its proportion correct yourself)", args.study)
    choices = sorted(trials["n_alternatives"].unique())
    if len(choices) != 1:
        raise UserError(f"the sessions ran different numbers of alternatives ({choices}); analyse them apart", args.study)
    n = int(choices[0])
    others = [name for name in facts.factors if name != level and name in trials and trials[name].nunique() > 1]
    fits = fit_psychometric_table(trials, level_column=level, group_columns=["participant", *others],
                                  correct_column="correct", options=nafc_options(n), n_jobs=args.n_jobs)
    fits = in_level_units(fits, level)  # threshold_fraction for contrast_fraction, threshold_D for level_D
    threshold = "threshold" + level_suffix(level)
    usable = fits[fits["status"].isin(USABLE_STATUSES)]
    means = t_summary(usable, others, [threshold], 0.95)
    args.results.mkdir(parents=True, exist_ok=True)
    write_csv(fits, results_file(args.results, args.study, "n_afc_fits", "csv"))
    write_json(results_file(args.results, args.study), {
        **provenance(facts, "n_afc", args.pool_protocols), "simulated": ds.simulated, "n_alternatives": n,
        "guess": 1.0 / n, "target_p": (1.0 + 1.0 / n) / 2.0, "level_factor": level,
        "level_unit": level_unit_text(level), "conditions": others,
        "fits_by_status": fits["status"].value_counts().to_dict(),
        "thresholds": means.to_dict("records"),
    })
    _figure(trials, fits, means, level, others, n, args.study, ds.simulated, out_path(args))
    confidence_analysis(trials, [*others, level], args.study, args.results, out_path(args), ds.simulated)  # if rated
    print(means.to_string(index=False))
    return 0


def _figure(trials, fits, means, level, others, n, study, simulated, out) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from psyop.figures.output import save_figure
    from psyop.figures.study_figures import mark_simulated
    from psyop.statistics.level_units import level_suffix
    from psyop.statistics.psychometric import USABLE_STATUSES, predicted_pc

    fig, (left, right) = plt.subplots(1, 2, figsize=(10.0, 4.0))
    share = trials.groupby(level)["correct"].mean()
    left.plot(share.index, share.to_numpy(), "o", color="k", label="all participants")
    grid = np.linspace(float(trials[level].min()), float(trials[level].max()), 200)
    suffix = level_suffix(level)
    for row in fits[fits["status"].isin(USABLE_STATUSES)].to_dict("records"):
        left.plot(grid, predicted_pc(grid, row["location" + suffix], row["width" + suffix], row["lapse"], guess=1.0 / n),
                  color="0.5", lw=0.6, alpha=0.6)
    left.axhline(1.0 / n, color="0.7", lw=0.8, ls=":")
    left.axhline((1.0 + 1.0 / n) / 2.0, color="0.7", lw=0.8, ls="--")
    left.set_xlabel(level)
    left.set_ylabel("proportion correct")
    left.set_ylim(0.0, 1.02)
    left.legend(fontsize=8, loc="lower right")
    x = np.arange(len(means))
    right.errorbar(x, means["mean"], yerr=[means["mean"] - means["ci_low"], means["ci_high"] - means["mean"]],
                   fmt="o", capsize=3)
    right.set_xticks(x, [", ".join(str(r[c]) for c in others) or "all" for r in means.to_dict("records")])
    right.set_ylabel(f"threshold ({level}; mean, 95 % CI)")
    right.set_xlabel(", ".join(others) or "condition")
    fig.suptitle(f"{n}-AFC: {study}")
    mark_simulated(fig, simulated)
    save_figure(fig, out)


if __name__ == "__main__":
    sys.exit(run(main))
