"""NC calibration (a with_against nulling study, protocols/examples/nc_calibration.yaml): each participant's
point of subjective stability (PSS), the signed rendered NC at which 'with' and 'against' are equally likely,
with its 95 % credible interval (psyop.statistics.nulling: psignifit, equal asymptotes).

Writes results/<study>_pss.csv (one row per participant: status, PSS, interval, sigma, lapse, flags),
results/<study>.json (the same, and for each participant with a PSS the protocol line that renders with it:
``display.rendering_nc: {mm: PSS}``) and figures/<study>_pss.png (proportion 'against' by rendered
NC, the fitted curve and the PSS of each participant). A censored PSS (beyond the NC levels rendered) is
reported as a bound, never as a number.
"""

from __future__ import annotations

import sys

import numpy as np
from _common import out_path, parser, provenance, require_columns, require_kind, results_file, run, write_csv, write_json

from psyop.statistics.studies import study_facts


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "figures/{study}_pss.png", study="nc_calibration")
    p.add_argument("--level-column", default="rendered_nc_mm",
                   help="the signed rendered NC of each trial, mm (default: the schedule's rendered_nc_mm)")
    args = p.parse_args(argv)
    import pandas as pd

    from psyop.statistics.dataset import load_dataset
    from psyop.statistics.nulling import fit_nulling, nulling_blocks, pss_text

    facts = study_facts(args.data, args.study)
    require_kind(facts, "with_against", "nc_calibration.py")
    ds = load_dataset(args.data, args.study)
    trials = ds.trials
    require_columns(trials, [args.level_column, "response", "participant"], str(args.data / args.study),
                    "give --level-column naming the trials' signed rendered NC (mm)")
    rows, blocks, summary, calibrated = [], {}, {}, {}
    for participant, group in trials.groupby("participant", sort=True):
        data = nulling_blocks(group, args.level_column)
        fit = fit_nulling(data, f"{args.study} sub-{participant}")
        blocks[participant] = (data, fit)
        rows.append({"participant": participant, **fit.as_row()})
        summary[f"{args.study} PSS: sub-{participant}"] = pss_text(fit)
        if fit.ok:
            calibrated[participant] = f"display.rendering_nc: {{mm: {fit.pss_mm:.2f}}}"
    table = pd.DataFrame(rows)
    args.results.mkdir(parents=True, exist_ok=True)
    write_csv(table, results_file(args.results, args.study, "pss", "csv"))
    n_ok = int((table["status"] == "ok").sum())
    summary[f"{args.study} participants with a PSS"] = f"{n_ok} of {len(table)}"
    write_json(results_file(args.results, args.study), {
        **provenance(facts, "nc_calibration", args.pool_protocols), "simulated": ds.simulated, "level_column": args.level_column,
        "ci_level": 0.95, "participants": table.to_dict("records"), "calibrated_rendering_nc": calibrated,
        "summary": summary,
    })
    _figure(blocks, args.study, ds.simulated, out_path(args))
    for participant, fit in ((r["participant"], blocks[r["participant"]][1]) for r in rows):
        print(f"sub-{participant}: PSS {pss_text(fit)}" + (f"  -> {calibrated[participant]}" if fit.ok else ""))
    return 0


def _figure(blocks, study: str, simulated: bool, out) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy.stats import norm

    from psyop.figures.output import save_figure
    from psyop.figures.study_figures import mark_simulated

    fig, ax = plt.subplots(figsize=(6.0, 4.0))
    for index, (participant, (data, fit)) in enumerate(blocks.items()):
        colour = plt.cm.tab10(index % 10)
        ax.plot(data[:, 0], data[:, 1] / data[:, 2], "o", color=colour, alpha=0.7, label=f"sub-{participant}")
        if fit.ok:
            x = np.linspace(fit.level_min_mm, fit.level_max_mm, 200)
            ax.plot(x, fit.lapse + (1 - 2 * fit.lapse) * norm.cdf((x - fit.pss_mm) / fit.sigma_mm), color=colour)
            ax.axvline(fit.pss_mm, color=colour, lw=0.8, ls="--")
    ax.axhline(0.5, color="0.6", lw=0.8)
    ax.set_xlabel("rendered NC (mm; 0 conventional, < 0 reversed)")
    ax.set_ylabel("proportion 'against the eye'")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title(f"NC calibration: {study}" if study != "nc_calibration" else "NC calibration")
    if len(blocks) <= 10:
        ax.legend(fontsize=7, loc="upper left")
    mark_simulated(fig, simulated)
    save_figure(fig, out)


if __name__ == "__main__":
    sys.exit(run(main))
