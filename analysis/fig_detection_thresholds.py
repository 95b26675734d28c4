"""Detection thresholds by back-surface distance (subject thresholds with 95 % CIs, mean +- SE).

Reads the fit cache (results/detection_fits.csv); writes results/detection_thresholds.json
with the grand mean threshold and a one-way rm-ANOVA of thresholds over back distance.
"""

from __future__ import annotations

import sys
from pathlib import Path

from _common import parser, read_fits, write_json

from psyop.figures.output import save_figure
from psyop.figures.study_figures import plot_thresholds
from psyop.statistics.anova import rm_anova
from psyop.statistics.dataset import is_simulated
from psyop.statistics.formatting import format_anova


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "figures/fig_detection_thresholds.png")
    p.add_argument("--fits", type=Path, default=Path("results/detection_fits.csv"))
    args = p.parse_args(argv)
    fits = read_fits(args.fits)
    simulated = is_simulated(args.data)
    clean = fits[fits["flags"] == ""]
    per_back = clean.groupby("back_D")["threshold_D"].agg(["mean", "std", "count"]).reset_index()
    payload = {
        "study": "detection", "simulated": simulated, "n_subjects": int(fits["participant"].nunique()),
        "n_fits": len(fits), "n_flagged": int((fits["flags"] != "").sum()),
        "flagged": fits.loc[fits["flags"] != "", ["participant", "back_D", "flags"]].to_dict("records"),
        "mean_threshold_D": float(clean["threshold_D"].mean()),
        "per_back": per_back.to_dict("records"),
        "summary": {"detection threshold (mean over subjects and back distances)": f"{clean['threshold_D'].mean():.2f} D"},
    }
    try:
        aov = rm_anova(clean, "threshold_D", "back_D")
    except ValueError as exc:  # too few complete subjects: say so instead of a number
        payload["summary"]["effect of back distance on threshold (rm-ANOVA)"] = f"not computed: {exc}"
    else:
        payload["anova_back_D"] = aov.table.to_dict("records")
        payload["anova_dropped"] = aov.dropped.to_dict("records")
        payload["summary"]["effect of back distance on threshold (rm-ANOVA)"] = format_anova(aov.table.iloc[0])
    write_json(args.results / "detection_thresholds.json", payload)
    fig = plot_thresholds(fits, "back_D", "back surface distance (D)", "Detection thresholds", simulated=simulated)
    save_figure(fig, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
