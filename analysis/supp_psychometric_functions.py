"""Supplement: every subject's psychometric functions (rows) for each condition (columns).

    python analysis/supp_psychometric_functions.py --study detection --fits results/detection_fits.csv \
        --out figures/supp_psychometric_detection.png
"""

from __future__ import annotations

import sys
from pathlib import Path

from _common import parser, read_fits, run

from psyop.figures.output import save_figure
from psyop.figures.study_figures import plot_psychometric_grid
from psyop.statistics.dataset import load_dataset

CONDITION = {"detection": "back_D", "discrimination": "offset_D"}


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "figures/supp_psychometric_detection.png")
    p.add_argument("--study", choices=sorted(CONDITION), default="detection")
    p.add_argument("--fits", type=Path, default=None)
    args = p.parse_args(argv)
    fits_path = args.fits or Path("results") / f"{args.study}_fits.csv"
    fits = read_fits(fits_path, data=args.data, study=args.study)
    ds = load_dataset(args.data, args.study)
    cond = CONDITION[args.study]
    answered = ds.trials[ds.trials["correct"].notna()].copy()
    answered["correct"] = answered["correct"].astype(bool)
    blocks = (answered.groupby(["participant", cond, "level_D"])["correct"].agg(["sum", "size"])
              .rename(columns={"sum": "n_correct", "size": "n_total"}).reset_index())
    fig = plot_psychometric_grid(blocks, fits, cond, f"Psychometric functions: {args.study}", simulated=ds.simulated)
    save_figure(fig, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
