"""Adaptive runs (staircase, QUEST+): a track plot per participant x condition (level by trial,
reversals marked, the procedure's estimate and 95 % interval, the psychometric fit's threshold) and
a table of reversal-based, procedure and fit-based estimates side by side.

    python analysis/adaptive_tracks.py --study detection_quest_plus --data data

Writes figures/<study>_tracks.png, results/<study>_adaptive.csv and results/<study>_adaptive.json.
The fit columns come from results/<study>_fits.csv (made when missing, as the other scripts do).
"""

from __future__ import annotations

import sys
from pathlib import Path

from _common import out_path, parser, provenance, read_fits, require_columns, results_file, run, write_csv, write_json
from _twoafc import check_two_interval, condition_column, level_column, with_condition_column

from psyop.errors import UserError
from psyop.figures.adaptive_figures import plot_tracks
from psyop.figures.output import save_figure
from psyop.statistics.adaptive_estimates import estimates_table, mark_reversals
from psyop.statistics.dataset import is_simulated, load_dataset
from psyop.statistics.studies import study_facts


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "figures/{study}_tracks.png", study="detection_quest_plus")
    p.add_argument("--fits", type=Path, default=None, help="fit cache (default results/<study>_fits.csv)")
    args = p.parse_args(argv)
    facts = study_facts(args.data, args.study)
    check_two_interval(facts, "adaptive_tracks.py")
    fits_path = args.fits or results_file(args.results, args.study, "fits", "csv")
    fits = read_fits(fits_path) if args.fits else read_fits(fits_path, data=args.data, study=args.study)
    cond = condition_column(facts, fits["condition_column"].iloc[0] if "condition_column" in fits and len(fits) else None)
    level = facts.factor(level_column(facts, None))
    unit = level.name.rsplit("_", 1)[-1]
    trials = load_dataset(args.data, args.study).trials
    if "adaptive_procedure" not in trials:
        raise UserError(f"study {args.study!r} has no adaptive columns (adaptive_procedure ...): not an adaptive "
                        "run; its levels were fixed by the protocol", str(args.data / args.study))
    trials = with_condition_column(trials[trials["adaptive_procedure"].astype(str) != ""], facts, cond)
    require_columns(trials, [cond, level.name, "participant"], str(args.data / args.study), "refit with this psyop")
    groups = ["participant", cond]
    table = estimates_table(trials, level.name, unit, groups, fits)
    write_csv(table, results_file(args.results, args.study, "adaptive", "csv"))
    write_json(results_file(args.results, args.study, "adaptive"), {
        **provenance(facts, "adaptive_tracks", args.pool_protocols), "condition_column": cond,
        "level_column": level.name, "tracks": table.to_dict("records"),
        "summary": {"adaptive tracks": f"{len(table)} tracks ({', '.join(sorted(table['procedure'].unique()))}); "
                    f"{int(table['n_reversals'].sum())} reversals; fit status: "
                    f"{table['fit_status'].value_counts().to_dict() if 'fit_status' in table else 'no fits'}"}})
    tracks = mark_reversals(trials, groups)
    fig = plot_tracks(tracks, table, cond, level.name, unit, f"Adaptive tracks: {args.study}",
                      simulated=is_simulated(args.data))
    save_figure(fig, out_path(args))
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
