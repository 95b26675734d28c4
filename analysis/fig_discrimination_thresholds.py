"""Thresholds against a numeric condition, with the linear fit (the paper's discrimination figure:
0.11 x + 0.38 D); any two-interval study with a numeric condition factor.

Reads results/<study>_fits.csv; writes results/<study>_fit.json. The OLS line uses the usable fits
(psyop.statistics.psychometric.usable_for_analysis); beside it a censored-normal (Tobit) line enters
censored thresholds at their bounds (psyop.statistics.censored), so none is silently dropped. Axis labels come from
the protocol's factor names, descriptions and units.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd
from _common import out_path, parser, provenance, read_fits, require_columns, results_file, run, write_json
import fit_psychometric
from _twoafc import check_two_interval, condition_column, level_column

from psyop.errors import UserError
from psyop.figures.output import save_figure
from psyop.figures.study_figures import caption, plot_thresholds
from psyop.statistics.censored import censored_report, fit_fates
from psyop.statistics.dataset import is_simulated
from psyop.statistics.formatting import format_linear_fit
from psyop.statistics.psychometric import interval_report, usable_for_analysis
from psyop.statistics.regression import linear_fit
from psyop.statistics.small_sample import MIN_RELIABLE_DF
from psyop.statistics.studies import study_facts


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "figures/{study}_thresholds.png", study="discrimination")
    p.add_argument("--fits", type=Path, default=None, help="fit cache (default results/<study>_fits.csv)")
    p.add_argument("--offset-column", "--condition-column", dest="condition_column", default=None,
                   help="the numeric condition column (default: the fit cache's)")
    p.add_argument("--level-column", default=None, help="default: the response's level_factor")
    args = p.parse_args(argv)
    facts = study_facts(args.data, args.study)
    check_two_interval(facts, "fig_discrimination_thresholds.py")
    fits_path = args.fits or results_file(args.results, args.study, "fits", "csv")
    # a cache given by --fits is the user's: never rebuilt; the default one is rebuilt if unreadable
    fits = read_fits(fits_path) if args.fits else read_fits(fits_path, data=args.data, study=args.study,
                                                                  rebuild=fit_psychometric.main)
    cached = fits["condition_column"].iloc[0] if "condition_column" in fits and len(fits) else None
    cond = condition_column(facts, args.condition_column or cached)
    require_columns(fits, [cond, "threshold_D", "participant"], str(fits_path),
                    "give --condition-column naming the column the fits were made over")
    if not pd.api.types.is_numeric_dtype(fits[cond]):
        raise UserError(f"condition {cond!r} is not numeric: a linear fit needs numbers; use "
                        "analysis/fig_detection_thresholds.py for thresholds by condition", str(fits_path))
    level = facts.factor(level_column(facts, args.level_column))
    unit = level.unit or "level units"
    simulated = is_simulated(args.data)
    clean, left_out = usable_for_analysis(fits)
    fit = linear_fit(clean, cond, "threshold_D")
    label = facts.factor(cond).label
    key = ("discrimination threshold vs offset (linear fit)" if cond == "offset_D"
           else f"{args.study} threshold vs {label} (linear fit)")
    censored = censored_report(fits, cond, unit, numeric=True)
    write_json(results_file(args.results, args.study, "fit"), {
        **provenance(facts, "linear_fit", args.pool_protocols), "simulated": simulated, "n_subjects": int(fits["participant"].nunique()),
        "condition_column": cond, "level_column": level.name, "level_unit": level.unit,
        "n_fits": len(fits), "n_left_out": int(sum(left_out.values())), "left_out_by_status": left_out,
        "left_out": fits.loc[~fits.index.isin(clean.index), ["participant", cond, "status"]].to_dict("records"),
        "linear_fit": fit.__dict__,
        "summary": {key: format_linear_fit(fit, unit)
                    + f"; {sum(left_out.values())} of {len(fits)} fits left out: {left_out or 'none'}",
                    "fit intervals": interval_report(fits)["text"],
                    "censored thresholds": censored["headline"],
                    f"{key}, censored-data model (Tobit) slope": censored.get("text_slope", censored["text_mean"])},
        "censored": censored, "fit_intervals": interval_report(fits), "fits": fit_fates(fits, cond),
    })
    title = "Discrimination thresholds" if args.study == "discrimination" else f"Thresholds: {args.study}"
    fig = plot_thresholds(fits, cond, label, title, line=(fit.slope, fit.intercept), simulated=simulated,
                          level_unit=unit)
    caption(fig, line_caption(fit.n, int(sum(left_out.values())), censored))
    save_figure(fig, out_path(args))
    return 0


def line_caption(n_fits: int, n_left_out: int, censored: dict) -> str:
    """The figure's caption: the drawn line's model (least squares over the usable fits, its df and flag)
    and the censored-data line fitted beside it (its slope, df and flags, or why it was not fitted).

    >>> text = line_caption(5, 1, {"line": {"df_interval": 2, "low_df": True, "n_clusters": 3}})
    >>> text.splitlines()[1:]  # doctest: +NORMALIZE_WHITESPACE
    ['Line: least-squares fit of the 5 usable fits (t on 3 df) [FLAGGED: low_df]; 1 fit left out.',
     'With the censored fits (results/summary.md): censored-normal (Tobit) line, participant-clustered SEs,
     t on 2 df [FLAGGED: low_df].']
    """
    df = n_fits - 2
    flag = " [FLAGGED: low_df]" if df < MIN_RELIABLE_DF else ""
    line = censored.get("line")
    if line is None:
        tobit = f"censored-normal (Tobit) line NOT FITTED ({censored.get('text_mean', 'no censored-data model')})"
    else:
        se = "participant-clustered SEs" if line["n_clusters"] else "fits independent"
        tobit = (f"censored-normal (Tobit) line, {se}, t on {line['df_interval']} df"
                 + (" [FLAGGED: low_df]" if line["low_df"] else ""))
    return ("Grey: participants' thresholds, 95 % CIs; open triangles: censored fits at their bound.\n"
            f"Line: least-squares fit of the {n_fits} usable fits (t on {df} df){flag}; "
            f"{n_left_out} fit{'' if n_left_out == 1 else 's'} left out.\n"
            f"With the censored fits (results/summary.md): {tobit}.")


if __name__ == "__main__":
    sys.exit(run(main))
