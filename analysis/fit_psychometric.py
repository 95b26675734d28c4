"""Fit every subject x condition psychometric function of a threshold (two-interval) study; cache to CSV.

    python analysis/fit_psychometric.py --study detection --data data --out results/detection_fits.csv

The condition column is the protocol's factor other than the level factor (or --condition-column); a
design with several such factors (numbers and words mixed) is fitted per crossed cell, in the column
``condition_cell`` ("back_D=1, mode=ocular"; psyop.statistics.conditions);
the level column is the response's level_factor (or --level-column). The figure scripts read this
cache, so the slow fits run only when data or code change.
"""

from __future__ import annotations

import sys

from _common import out_path, parser, require_columns, run, write_csv
from _twoafc import check_two_interval, condition_column, level_column, with_condition_column

from psyop.statistics.dataset import load_dataset
from psyop.statistics.psychometric import FitOptions, GridSpec, fit_psychometric_table
from psyop.statistics.studies import study_facts


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "{results}/{study}_fits.csv", study="detection")
    p.add_argument("--condition-column", default=None, help="the condition column (default: the protocol's factor "
                   "other than the level factor)")
    p.add_argument("--level-column", default=None, help="the level column (default: the response's level_factor)")
    p.add_argument("--n-jobs", type=int, default=-1, help="processes (-1: all cores)")
    p.add_argument("--grid-scale", type=float, default=1.0, help="psignifit grid resolution factor")
    p.add_argument("--n-bootstrap", type=int, default=2000)
    args = p.parse_args(argv)
    facts = study_facts(args.data, args.study)
    check_two_interval(facts, "fit_psychometric.py")
    ds = load_dataset(args.data, args.study)
    condition = condition_column(facts, args.condition_column)
    level = level_column(facts, args.level_column)
    trials = with_condition_column(ds.trials, facts, condition)
    require_columns(trials, [condition, level], str(args.data / args.study),
                    "give --condition-column / --level-column naming the study's factors")
    options = FitOptions(grid=GridSpec().scaled(args.grid_scale), n_bootstrap=args.n_bootstrap)
    table = fit_psychometric_table(trials, level, ["participant", condition],
                                   options=options, n_jobs=args.n_jobs)
    if "adaptive_procedure" in ds.trials:  # adaptive levels: the procedure's own estimate beside the fit
        from psyop.adaptive.results import with_procedure_estimates

        table = with_procedure_estimates(table, trials, ["participant", condition])
    table.insert(0, "study", args.study)
    table["simulated"] = ds.simulated
    table["condition_column"] = condition
    table["level_column"] = level
    out = out_path(args)
    write_csv(table, out)
    counts = table["status"].value_counts().to_dict()
    print(f"{args.study}: {len(table)} fits, status {counts} -> {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
