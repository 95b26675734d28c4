"""Discrimination thresholds against relative offset, with the linear fit (paper: 0.11 x + 0.38 D).

Reads results/discrimination_fits.csv; writes results/discrimination_fit.json.
"""

from __future__ import annotations

import sys
from pathlib import Path

from _common import parser, read_fits, write_json

from psyop.figures.output import save_figure
from psyop.figures.study_figures import plot_thresholds
from psyop.statistics.dataset import is_simulated
from psyop.statistics.formatting import format_linear_fit
from psyop.statistics.regression import linear_fit


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "figures/fig_discrimination_thresholds.png")
    p.add_argument("--fits", type=Path, default=Path("results/discrimination_fits.csv"))
    p.add_argument("--offset-column", default="offset_D")
    args = p.parse_args(argv)
    fits = read_fits(args.fits)
    simulated = is_simulated(args.data)
    clean = fits[fits["flags"] == ""]
    fit = linear_fit(clean, args.offset_column, "threshold_D")
    write_json(args.results / "discrimination_fit.json", {
        "study": "discrimination", "simulated": simulated, "n_subjects": int(fits["participant"].nunique()),
        "n_flagged": int((fits["flags"] != "").sum()),
        "flagged": fits.loc[fits["flags"] != "", ["participant", args.offset_column, "flags"]].to_dict("records"),
        "linear_fit": fit.__dict__,
        "summary": {"discrimination threshold vs offset (linear fit)": format_linear_fit(fit, "D")},
    })
    fig = plot_thresholds(fits, args.offset_column, "relative offset (D)", "Discrimination thresholds",
                          line=(fit.slope, fit.intercept), simulated=simulated)
    save_figure(fig, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
