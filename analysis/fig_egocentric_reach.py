"""Egocentric blind reaching: reach against target (fractions of arm reach) per rendering
condition. Primary test: a linear mixed model with a random intercept and slope per participant
(MixedLM; falls back with a stated reason); the paper's pooled multiple regression beside it.

Reach fraction = ``reach_m / arm_reach_m`` (or a ``reach_fraction`` column if the log has one);
``reach_m`` is the hand's distance along the horizontal eye-to-target direction (psyop/session/reach.py).
The rendering and target columns are the response's ``rendering_factor`` and ``target_factor``.
Writes results/<study>_fits.csv and results/<study>.json.
"""

from __future__ import annotations

import sys

from _common import out_path, parser, provenance, require_columns, require_kind, results_file, run, write_csv, write_json

from psyop.errors import UserError
from psyop.figures.output import save_figure
from psyop.figures.study_figures import plot_reach
from psyop.statistics.dataset import load_dataset
from psyop.statistics.formatting import format_condition_comparison, format_mixed_comparison
from psyop.statistics.regression import condition_interaction, linear_fits_by, mixed_condition_comparison
from psyop.statistics.studies import study_facts


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "figures/{study}_reach.png", study="egocentric")
    p.add_argument("--reference", default=None, help="reference rendering condition (default: disabled, else the "
                   "first level)")
    args = p.parse_args(argv)
    facts = study_facts(args.data, args.study)
    require_kind(facts, "reach", "fig_egocentric_reach.py")
    rendering = facts.response_column("rendering_factor", "rendering")
    target = facts.response_column("target_factor", "target_fraction")
    ds = load_dataset(args.data, args.study)
    t = ds.trials.copy()
    require_columns(t, [rendering, target, "participant"], str(args.data / args.study),
                    "the reach study's rendering and target factors must be trial columns")
    if "reach_fraction" not in t:
        if "arm_reach_m" not in t:
            raise UserError("egocentric trials need reach_fraction or arm_reach_m to express reach as a fraction",
                            str(args.data / args.study))
        t["reach_fraction"] = t["reach_m"] / t["arm_reach_m"]
    t = t[t["reach_fraction"].notna()]
    levels = sorted(t[rendering].astype(str).unique())
    reference = args.reference or ("disabled" if "disabled" in levels else levels[0])
    if reference not in levels:
        raise UserError(f"--reference {reference!r} is not a level of {rendering!r} ({', '.join(levels)})", "--reference")
    fits = linear_fits_by(t, target, "reach_fraction", rendering)
    comparison = condition_interaction(t, target, "reach_fraction", rendering, reference)
    mixed = mixed_condition_comparison(t, target, "reach_fraction", rendering, reference=reference)
    args.results.mkdir(parents=True, exist_ok=True)
    write_csv(fits, results_file(args.results, args.study, "fits", "csv"))
    summary = {f"reach vs target, {r[rendering]}": f"slope = {r['slope']:.3f}, intercept = {r['intercept']:.3f}, "
               f"R^2 = {r['r2']:.2f}" for _, r in fits.iterrows()}
    summary["reach: condition difference, primary (subject-aware)"] = format_mixed_comparison(mixed)
    summary["reach: condition difference, pooled multiple regression (trials as independent; the paper's)"] = \
        format_condition_comparison(comparison)
    write_json(results_file(args.results, args.study), {
        **provenance(facts, "reach", args.pool_protocols), "simulated": ds.simulated, "n_subjects": int(t["participant"].nunique()),
        "rendering_column": rendering, "target_column": target,
        "fits": fits.to_dict("records"), "comparison": comparison.__dict__, "mixed": mixed.__dict__, "summary": summary,
    })
    title = "Egocentric blind reaching" if args.study == "egocentric" else f"Blind reaching: {args.study}"
    save_figure(plot_reach(t, fits, x=target, condition=rendering, simulated=ds.simulated, title=title,
                                test_model=mixed.method.split(" (")[0] + (" [FLAGGED: " + mixed.flags + "]" if mixed.flags else "")),
                out_path(args))
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
