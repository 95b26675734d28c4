"""Detection thresholds by back-surface distance (subject thresholds with 95 % CIs, mean ± SE).

Reads the fit cache (results/detection_fits.csv); writes results/detection_thresholds.json
with the grand mean threshold (and its 95 % t-interval over participants) and a one-way
rm-ANOVA of thresholds over back distance. Fits whose status is not usable (censored,
lapse at bound, bimodal, grid edge, no fit) are left out by the documented rule
(psyop.statistics.psychometric.usable_for_analysis) and counted by status.
"""

from __future__ import annotations

import sys
from pathlib import Path

from _common import parser, read_fits, run, write_json

from psyop.figures.output import save_figure
from psyop.figures.study_figures import plot_thresholds
from psyop.statistics.anova import rm_anova
from psyop.statistics.dataset import is_simulated
from psyop.statistics.formatting import format_anova
from psyop.statistics.psychometric import usable_for_analysis
from scipy import stats


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "figures/fig_detection_thresholds.png")
    p.add_argument("--fits", type=Path, default=Path("results/detection_fits.csv"))
    args = p.parse_args(argv)
    fits = read_fits(args.fits, data=args.data, study="detection")
    simulated = is_simulated(args.data)
    clean, left_out = usable_for_analysis(fits)
    per_subject = clean.groupby("participant")["threshold_D"].mean()
    per_back = clean.groupby("back_D")["threshold_D"].agg(["mean", "std", "count"]).reset_index()
    n = len(per_subject)
    half = float(stats.t.ppf(0.975, n - 1) * per_subject.std(ddof=1) / n ** 0.5) if n > 1 else float("nan")
    mean = float(per_subject.mean())
    payload = {
        "study": "detection", "simulated": simulated, "n_subjects": int(fits["participant"].nunique()),
        "n_fits": len(fits), "n_left_out": int(sum(left_out.values())), "left_out_by_status": left_out,
        "left_out": fits.loc[~fits.index.isin(clean.index), ["participant", "back_D", "status"]].to_dict("records"),
        "mean_threshold_D": mean, "mean_threshold_ci_D": [mean - half, mean + half],
        "per_back": per_back.to_dict("records"),
        "summary": {"detection threshold (mean over subjects and back distances)":
                    f"{mean:.2f} D [95 % CI {mean - half:.2f}, {mean + half:.2f}; {n} participants; "
                    f"{sum(left_out.values())} of {len(fits)} fits left out: {left_out or 'none'}]"},
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
    sys.exit(run(main))
