"""Ordinal depth: proportion correct by rendering mode and separation, 3 x 2 rm-ANOVA (GG),
Bonferroni post-hoc paired t-tests per separation with significance stars.

Writes results/ordinal_cells.csv, ordinal_anova.csv, ordinal_posthoc.csv, ordinal.json.
"""

from __future__ import annotations

import sys

from _common import parser, run, write_csv, write_json

from psyop.figures.output import save_figure
from psyop.figures.study_figures import plot_ordinal
from psyop.statistics.anova import cell_means, posthoc_paired, rm_anova
from psyop.statistics.dataset import load_dataset
from psyop.statistics.formatting import format_anova, format_ttest


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "figures/fig_ordinal_depth.png", study="ordinal")
    p.add_argument("--bonferroni-family", choices=["per_level", "all"], default="per_level",
                   help="per_level: correct over the 3 mode pairs within each separation (the paper's "
                        "'pairwise t-tests between rendering modes at each separation distance'); all: over all 6")
    args = p.parse_args(argv)
    ds = load_dataset(args.data, args.study)
    cells = cell_means(ds.trials, "correct", ["mode", "separation_D"])
    aov = rm_anova(cells, "correct", ["mode", "separation_D"])
    posthoc = posthoc_paired(cells, "correct", "mode", by="separation_D", family=args.bonferroni_family)
    family_text = ("the 3 mode pairs within each separation (m = 3)" if args.bonferroni_family == "per_level"
                   else f"all {len(posthoc)} mode pairs across separations (m = {len(posthoc)})")
    args.results.mkdir(parents=True, exist_ok=True)
    write_csv(cells, args.results / "ordinal_cells.csv")
    write_csv(aov.table, args.results / "ordinal_anova.csv")
    write_csv(posthoc, args.results / "ordinal_posthoc.csv")
    means = cells.groupby(["mode", "separation_D"])["correct"].mean()
    summary = {f"ordinal rm-ANOVA: {r['effect']}": format_anova(r) for _, r in aov.table.iterrows()}
    for _, r in posthoc.iterrows():
        summary[f"ordinal post-hoc at {r['separation_D']:g} D: {r['A']} vs {r['B']}"] = format_ttest(r)
    for (mode, sep), m in means.items():
        summary[f"ordinal proportion correct: {mode}, {sep:g} D"] = f"{100 * m:.1f}%"
    write_json(args.results / "ordinal.json", {
        "study": "ordinal", "simulated": ds.simulated, "n_subjects": aov.n_subjects,
        "dropped": aov.dropped.to_dict("records"), "anova": aov.table.to_dict("records"),
        "posthoc": posthoc.to_dict("records"), "bonferroni_family": args.bonferroni_family,
        "bonferroni_family_text": family_text, "summary": summary,
    })
    save_figure(plot_ordinal(cells[~cells["participant"].isin(aov.dropped["subject"])], posthoc,
                             simulated=ds.simulated), args.out)
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
