"""Discrimination thresholds against relative offset, with the linear fit (paper: 0.11 x + 0.38 D).

Reads results/discrimination_fits.csv; writes results/discrimination_fit.json. Fits whose
status is not usable are left out (psyop.statistics.psychometric.usable_for_analysis) and counted.
"""

from __future__ import annotations

import sys
from pathlib import Path

from _common import parser, read_fits, run, write_json

from psyop.figures.output import save_figure
from psyop.figures.study_figures import plot_thresholds
from psyop.statistics.dataset import is_simulated
from psyop.statistics.formatting import format_linear_fit
from psyop.statistics.psychometric import usable_for_analysis
from psyop.statistics.regression import linear_fit


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "figures/fig_discrimination_thresholds.png")
    p.add_argument("--fits", type=Path, default=Path("results/discrimination_fits.csv"))
    p.add_argument("--offset-column", default="offset_D")
    args = p.parse_args(argv)
    fits = read_fits(args.fits, data=args.data, study="discrimination")
    simulated = is_simulated(args.data)
    clean, left_out = usable_for_analysis(fits)
    fit = linear_fit(clean, args.offset_column, "threshold_D")
    write_json(args.results / "discrimination_fit.json", {
        "study": "discrimination", "simulated": simulated, "n_subjects": int(fits["participant"].nunique()),
        "n_fits": len(fits), "n_left_out": int(sum(left_out.values())), "left_out_by_status": left_out,
        "left_out": fits.loc[~fits.index.isin(clean.index), ["participant", args.offset_column, "status"]].to_dict("records"),
        "linear_fit": fit.__dict__,
        "summary": {"discrimination threshold vs offset (linear fit)": format_linear_fit(fit, "D")
                    + f"; {sum(left_out.values())} of {len(fits)} fits left out: {left_out or 'none'}"},
    })
    fig = plot_thresholds(fits, args.offset_column, "relative offset (D)", "Discrimination thresholds",
                          line=(fit.slope, fit.intercept), simulated=simulated)
    save_figure(fig, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
