"""Supplement: every subject's psychometric functions (rows) for each condition (columns), for any
two-interval study.

    python analysis/supp_psychometric_functions.py --study detection --fits results/detection_fits.csv \
        --out figures/supp_psychometric_detection.png

The condition and level columns come from the fit cache (the protocol's factors), or are given.
"""

from __future__ import annotations

import sys
from pathlib import Path

from _common import out_path, parser, read_fits, require_columns, results_file, run
import fit_psychometric
from _twoafc import check_two_interval, condition_column, level_column, with_condition_column

from psyop.figures.output import save_figure
from psyop.figures.study_figures import plot_psychometric_grid
from psyop.statistics.dataset import load_dataset
from psyop.statistics.studies import study_facts


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "figures/supp_psychometric_{study}.png", study="detection")
    p.add_argument("--fits", type=Path, default=None, help="fit cache (default results/<study>_fits.csv)")
    p.add_argument("--condition-column", default=None, help="default: the fit cache's")
    p.add_argument("--level-column", default=None, help="default: the fit cache's (the response's level_factor)")
    args = p.parse_args(argv)
    facts = study_facts(args.data, args.study)
    check_two_interval(facts, "supp_psychometric_functions.py")
    fits_path = args.fits or results_file(args.results, args.study, "fits", "csv")
    # a cache given by --fits is the user's: never rebuilt; the default one is rebuilt if unreadable
    fits = read_fits(fits_path) if args.fits else read_fits(fits_path, data=args.data, study=args.study,
                                                                  rebuild=fit_psychometric.main)
    first = fits.iloc[0] if len(fits) else {}
    cond = condition_column(facts, args.condition_column or (first.get("condition_column") if len(fits) else None))
    level = level_column(facts, args.level_column or (first.get("level_column") if len(fits) else None))
    require_columns(fits, [cond, "participant"], str(fits_path), "give --condition-column")
    ds = load_dataset(args.data, args.study)
    trials = with_condition_column(ds.trials, facts, cond)
    require_columns(trials, [cond, level, "correct"], str(args.data / args.study),
                    "give --condition-column / --level-column naming the study's factors")
    answered = trials[trials["correct"].notna()].copy()
    answered["correct"] = answered["correct"].astype(bool)
    blocks = (answered.groupby(["participant", cond, level])["correct"].agg(["sum", "size"])
              .rename(columns={"sum": "n_correct", "size": "n_total"}).reset_index())
    fig = plot_psychometric_grid(blocks, fits, cond, f"Psychometric functions: {args.study}", simulated=ds.simulated,
                                 level_column=level, level_label=facts.factor(level).label)
    save_figure(fig, out_path(args))
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
