"""Egocentric blind reaching: reach against target (fractions of arm reach) per rendering
condition. Primary test: a linear mixed model with a random intercept and slope per participant
(MixedLM; falls back with a stated reason); the paper's pooled multiple regression beside it.

Reach fraction = ``reach_m / arm_reach_m`` (or a ``reach_fraction`` column if the log has one);
``reach_m`` is the hand's distance along the horizontal eye-to-target direction (psyop/session/reach.py).
Writes results/egocentric_fits.csv and results/egocentric.json.
"""

from __future__ import annotations

import sys

from _common import parser, run, write_csv, write_json

from psyop.errors import UserError
from psyop.figures.output import save_figure
from psyop.figures.study_figures import plot_reach
from psyop.statistics.dataset import load_dataset
from psyop.statistics.formatting import format_condition_comparison, format_mixed_comparison
from psyop.statistics.regression import condition_interaction, linear_fits_by, mixed_condition_comparison


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "figures/fig_egocentric_reach.png", study="egocentric")
    p.add_argument("--reference", default="disabled", help="reference rendering condition")
    args = p.parse_args(argv)
    ds = load_dataset(args.data, args.study)
    t = ds.trials.copy()
    if "reach_fraction" not in t:
        if "arm_reach_m" not in t:
            raise UserError("egocentric trials need reach_fraction or arm_reach_m to express reach as a fraction",
                            str(args.data / "egocentric"))
        t["reach_fraction"] = t["reach_m"] / t["arm_reach_m"]
    t = t[t["reach_fraction"].notna()]
    fits = linear_fits_by(t, "target_fraction", "reach_fraction", "rendering")
    comparison = condition_interaction(t, "target_fraction", "reach_fraction", "rendering", args.reference)
    mixed = mixed_condition_comparison(t, "target_fraction", "reach_fraction", "rendering", reference=args.reference)
    args.results.mkdir(parents=True, exist_ok=True)
    write_csv(fits, args.results / "egocentric_fits.csv")
    summary = {f"reach vs target, {r['rendering']}": f"slope = {r['slope']:.3f}, intercept = {r['intercept']:.3f}, "
               f"R^2 = {r['r2']:.2f}" for _, r in fits.iterrows()}
    summary["reach: condition difference, primary (subject-aware)"] = format_mixed_comparison(mixed)
    summary["reach: condition difference, pooled multiple regression (trials as independent; the paper's)"] = \
        format_condition_comparison(comparison)
    write_json(args.results / "egocentric.json", {
        "study": "egocentric", "simulated": ds.simulated, "n_subjects": int(t["participant"].nunique()),
        "fits": fits.to_dict("records"), "comparison": comparison.__dict__, "mixed": mixed.__dict__, "summary": summary,
    })
    save_figure(plot_reach(t, fits, simulated=ds.simulated), args.out)
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
