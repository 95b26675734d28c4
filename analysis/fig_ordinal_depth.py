"""Ordinal depth (left/right nearer): proportion correct by rendering mode and separation, mode x
separation rm-ANOVA (GG), Bonferroni post-hoc paired t-tests per separation with significance stars.

Writes results/<study>_cells.csv, <study>_anova.csv, <study>_posthoc.csv and <study>.json. The
separation column is the response's ``separation_factor`` (or --separation-column).
"""

from __future__ import annotations

import sys

from _common import out_path, parser, provenance, require_columns, require_kind, results_file, run, write_csv, write_json
from _confidence import confidence_analysis

from psyop.figures.output import save_figure
from psyop.figures.study_figures import plot_ordinal
from psyop.statistics.anova import cell_means, posthoc_paired, rm_anova
from psyop.statistics.dataset import load_dataset
from psyop.statistics.formatting import format_anova, format_ttest
from psyop.statistics.studies import study_facts


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "figures/{study}_depth.png", study="ordinal")
    p.add_argument("--bonferroni-family", choices=["per_level", "all"], default="per_level",
                   help="per_level: correct over the 3 mode pairs within each separation (the paper's "
                        "'pairwise t-tests between rendering modes at each separation distance'); all: over all 6")
    p.add_argument("--separation-column", default=None, help="default: the response's separation_factor")
    args = p.parse_args(argv)
    facts = study_facts(args.data, args.study)
    require_kind(facts, "left_right_nearer", "fig_ordinal_depth.py")
    sep = args.separation_column or facts.response_column("separation_factor", "separation_D")
    ds = load_dataset(args.data, args.study)
    require_columns(ds.trials, ["mode", sep, "correct"], str(args.data / args.study),
                    "give --separation-column naming the study's separation factor")
    cells = cell_means(ds.trials, "correct", ["mode", sep])
    aov = rm_anova(cells, "correct", ["mode", sep])
    posthoc = posthoc_paired(cells, "correct", "mode", by=sep, family=args.bonferroni_family)
    family_text = ("the 3 mode pairs within each separation (m = 3)" if args.bonferroni_family == "per_level"
                   else f"all {len(posthoc)} mode pairs across separations (m = {len(posthoc)})")
    args.results.mkdir(parents=True, exist_ok=True)
    write_csv(cells, results_file(args.results, args.study, "cells", "csv"))
    write_csv(aov.table, results_file(args.results, args.study, "anova", "csv"))
    write_csv(posthoc, results_file(args.results, args.study, "posthoc", "csv"))
    means = cells.groupby(["mode", sep])["correct"].mean()
    unit = facts.factor(sep).unit or ""
    # the paper's labels ("ordinal rm-ANOVA: mode") for the paper's study; each study's own name otherwise
    summary = {f"{args.study} rm-ANOVA: {r['effect']}": format_anova(r) for _, r in aov.table.iterrows()}
    for _, r in posthoc.iterrows():
        summary[f"{args.study} post-hoc at {r[sep]:g} {unit}: {r['A']} vs {r['B']}".replace("  ", " ")] = format_ttest(r)
    for (mode, s), m in means.items():
        summary[f"{args.study} proportion correct: {mode}, {s:g} {unit}".rstrip()] = f"{100 * m:.1f}%"
    write_json(results_file(args.results, args.study), {
        **provenance(facts, "ordinal", args.pool_protocols), "simulated": ds.simulated, "n_subjects": aov.n_subjects,
        "separation_column": sep,
        "dropped": aov.dropped.to_dict("records"), "anova": aov.table.to_dict("records"),
        "posthoc": posthoc.to_dict("records"), "bonferroni_family": args.bonferroni_family,
        "bonferroni_family_text": family_text, "summary": summary,
    })
    title = "Ordinal depth" if args.study == "ordinal" else f"Ordinal depth: {args.study}"
    save_figure(plot_ordinal(cells[~cells["participant"].isin(aov.dropped["subject"])], posthoc,
                             simulated=ds.simulated, separation_column=sep, separation_label=facts.factor(sep).text,
                             separation_unit=unit, title=title), out_path(args))
    confidence_analysis(ds.trials, ["mode", sep], args.study, args.results, out_path(args), ds.simulated)  # if rated
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
