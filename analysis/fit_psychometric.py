"""Fit every subject x condition psychometric function of a threshold study; cache to CSV.

    python analysis/fit_psychometric.py --study detection --data data --out results/detection_fits.csv

The figure scripts read this cache, so the slow fits run only when data or code change.
"""

from __future__ import annotations

import sys

from _common import parser, run, write_csv

from psyop.statistics.dataset import load_dataset
from psyop.statistics.psychometric import FitOptions, GridSpec, fit_psychometric_table

CONDITION = {"detection": "back_D", "discrimination": "offset_D"}


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "results/detection_fits.csv")
    p.add_argument("--study", default="detection", help=f"study name ({', '.join(sorted(CONDITION))} or another "
                   "with --condition-column)")
    p.add_argument("--condition-column", default=None, help="override the condition column")
    p.add_argument("--level-column", default="level_D")
    p.add_argument("--n-jobs", type=int, default=-1, help="processes (-1: all cores)")
    p.add_argument("--grid-scale", type=float, default=1.0, help="psignifit grid resolution factor")
    p.add_argument("--n-bootstrap", type=int, default=2000)
    args = p.parse_args(argv)
    ds = load_dataset(args.data, args.study)
    condition = args.condition_column or CONDITION.get(args.study)
    if condition is None:
        p.error(f"--study {args.study}: give --condition-column (known studies: {', '.join(sorted(CONDITION))})")
    options = FitOptions(grid=GridSpec().scaled(args.grid_scale), n_bootstrap=args.n_bootstrap)
    table = fit_psychometric_table(ds.trials, args.level_column, ["participant", condition],
                                   options=options, n_jobs=args.n_jobs)
    if "adaptive_procedure" in ds.trials:  # adaptive levels: the procedure's own estimate beside the fit
        from psyop.adaptive.results import with_procedure_estimates

        table = with_procedure_estimates(table, ds.trials, ["participant", condition])
    table.insert(0, "study", args.study)
    table["simulated"] = ds.simulated
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_csv(table, args.out)
    counts = table["status"].value_counts().to_dict()
    print(f"{args.study}: {len(table)} fits, status {counts} -> {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
