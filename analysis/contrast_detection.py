"""Contrast thresholds of a two-interval study whose level is log10 Michelson contrast (a ``*_log10`` level factor
driving a grating's ``contrast: {michelson_log10: ...}``; protocols/examples/contrast_detection.yaml).

Reads the study's psychometric fits (results/<study>_fits.csv, analysis/fit_psychometric.py: the 75 % correct point
per participant and condition, in log10 contrast, with its 95 % interval) and reports each threshold as a Michelson
contrast (10 ** t, in %) and in dB (20 t, i.e. 20 log10 contrast), and per condition the mean of the usable
participants' log10 thresholds with a 95 % t interval, in all three units (the mean in log units is the geometric
mean contrast). Fits that are censored, or did not fit, are counted and listed, never averaged. Whether the sessions
ran on a calibrated display (session.json ``display_output``) is said in the JSON and on the figure: on an
uncalibrated one (or a session that recorded none) the contrasts are pixel-value contrasts, and both say so.

Writes results/<study>_contrast_thresholds.csv (one row per participant x condition), results/<study>_contrast.json
(the summary) and figures/<study>_contrast_thresholds.png.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd
from _common import out_path, parser, provenance, read_fits, results_file, run, write_csv, write_json
from _twoafc import check_two_interval

from psyop.statistics.studies import study_facts

#: log10 contrast -> dB (contrast, an amplitude ratio: 20 log10)
DB_PER_LOG10 = 20.0


def contrast_columns(fits: pd.DataFrame) -> pd.DataFrame:
    """Per fit: the threshold and its interval as log10 contrast, Michelson contrast (%) and dB."""
    out = fits.copy()
    for suffix in ("", "_ci_low", "_ci_high"):
        log10 = pd.to_numeric(out[f"threshold{suffix}_D"], errors="coerce").astype(float)
        out[f"threshold{suffix}_log10"] = log10
        out[f"threshold{suffix}_percent"] = 100.0 * np.power(10.0, log10)
        out[f"threshold{suffix}_dB"] = DB_PER_LOG10 * log10
    return out


def condition_means(usable: pd.DataFrame, conditions: list[str]) -> pd.DataFrame:
    """Per condition: the mean log10 threshold with its 95 % t interval, in log10, Michelson % and dB."""
    from psyop.statistics.signal_detection import t_summary

    means = t_summary(usable, conditions, ["threshold_log10"], 0.95)
    for column in ("mean", "ci_low", "ci_high"):
        means[f"{column}_percent"] = 100.0 * np.power(10.0, means[column].astype(float))
        means[f"{column}_dB"] = DB_PER_LOG10 * means[column].astype(float)
    return means


def display_note(data: Path, study: str) -> tuple[list[str], str]:
    """(the calibration files' SHA-256 the sessions ran through, a line saying so): from each session's
    session.json ``display_output``; a session on an uncalibrated display (or one that recorded none) makes the
    line say that its contrasts are pixel-value contrasts, not luminance contrasts."""
    from psyop.session.log.record import read_record_file
    from psyop.statistics.dataset import session_files

    outputs = [read_record_file(path.parent / "session.json") for path in session_files(data, study)]
    recorded = [r.display_output if r is not None else None for r in outputs]
    uncalibrated = sum(1 for o in recorded if o is not None and not o.calibrated)
    unknown = sum(1 for o in recorded if o is None)
    files = sorted({o.calibration_sha256 for o in recorded if o is not None and o.calibration_sha256})
    if uncalibrated or unknown:
        parts = ([f"uncalibrated in {uncalibrated}"] if uncalibrated else []) + \
            ([f"not recorded in {unknown}"] if unknown else [])
        return files, (f"UNCALIBRATED display ({', '.join(parts)} of {len(recorded)} sessions): their contrasts are "
                       "pixel-value contrasts, not luminance contrasts")
    return files, f"calibrated display ({len(files)} calibration file{'s' if len(files) != 1 else ''})"


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "figures/{study}_contrast_thresholds.png", study="contrast_detection")
    p.add_argument("--fits", type=Path, default=None, help="the fit cache (default results/<study>_fits.csv)")
    args = p.parse_args(argv)
    from psyop.errors import UserError
    from psyop.statistics.psychometric import USABLE_STATUSES

    facts = study_facts(args.data, args.study)
    check_two_interval(facts, "contrast_detection.py")
    level = facts.level_factor or ""
    if not level.endswith("_log10"):
        raise UserError(f"the level factor {level!r} is not in log10 contrast (a name ending in _log10, read by a "
                        "grating's contrast: {michelson_log10: {factor: ...}}); the contrast analysis does not apply",
                        args.study)
    fits = contrast_columns(read_fits(args.fits or results_file(args.results, args.study, "fits", "csv")))
    condition = str(fits["condition_column"].iloc[0]) if "condition_column" in fits and len(fits) else "condition"
    conditions = [condition] if condition in fits else []
    usable = fits[fits["status"].isin(USABLE_STATUSES)]
    means = condition_means(usable, conditions)
    simulated = bool(fits["simulated"].any()) if "simulated" in fits else False
    calibrations, note = display_note(args.data, args.study)
    write_csv(fits, results_file(args.results, args.study, "contrast_thresholds", "csv"))
    write_json(results_file(args.results, args.study, "contrast"), {
        **provenance(facts, "contrast_detection", args.pool_protocols), "simulated": simulated,
        "display": note, "calibration_sha256": calibrations, "level_factor": level, "threshold": "75 % correct (2AFC), per participant and condition",
        "units": {"log10": "log10 Michelson contrast", "percent": "Michelson contrast x 100",
                  "dB": "20 log10 Michelson contrast"},
        "fits_by_status": fits["status"].value_counts().to_dict(),
        "not_averaged": fits.loc[~fits["status"].isin(USABLE_STATUSES), ["participant", "status"]].to_dict("records"),
        "participants": usable[["participant", *conditions, "threshold_log10", "threshold_ci_low_log10",
                                "threshold_ci_high_log10", "threshold_percent", "threshold_dB"]].to_dict("records"),
        "means": means.to_dict("records"), "n_subjects": int(usable["participant"].nunique()),
        "summary": {f"threshold{'' if not conditions else ' ' + str(r.get(conditions[0]))}":
                    f"{r['mean_percent']:.3g} % Michelson ({r['mean_dB']:.1f} dB), 95 % CI {r['ci_low_percent']:.3g} to "
                    f"{r['ci_high_percent']:.3g} %, n = {r['n']}" for r in means.to_dict("records")} | {"display": note}})
    _figure(usable, means, conditions, f"{args.study}: contrast thresholds; {note}", simulated, out_path(args))
    print(note)
    print(means[[*conditions, "n", "mean_percent", "ci_low_percent", "ci_high_percent", "mean_dB"]]
          .to_string(index=False))
    return 0


def _figure(usable: pd.DataFrame, means: pd.DataFrame, conditions: list[str], title: str, simulated: bool,
            out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from psyop.figures.output import save_figure
    from psyop.figures.study_figures import mark_simulated

    fig, ax = plt.subplots(figsize=(6.0, 4.0))
    labels = [", ".join(str(r[c]) for c in conditions) or "all" for r in means.to_dict("records")]
    for x, row in enumerate(means.to_dict("records")):
        mine = usable if not conditions else usable[usable[conditions[0]] == row[conditions[0]]]
        jitter = np.linspace(-0.15, 0.15, max(len(mine), 1))[: len(mine)]
        ax.errorbar(x + jitter, mine["threshold_percent"], fmt="o", color="0.6", ms=4,
                    yerr=[mine["threshold_percent"] - mine["threshold_ci_low_percent"],
                          mine["threshold_ci_high_percent"] - mine["threshold_percent"]], lw=0.8, capsize=2)
        ax.errorbar([x + 0.3], [row["mean_percent"]], yerr=[[row["mean_percent"] - row["ci_low_percent"]],
                                                             [row["ci_high_percent"] - row["mean_percent"]]],
                    fmt="s", color="k", capsize=4)
        ax.annotate(f"{row['mean_percent']:.3g} % ({row['mean_dB']:.1f} dB)", (x + 0.35, row["mean_percent"]),
                    fontsize=8, va="center")
    ax.set_yscale("log")
    ax.set_xticks(range(len(labels)), labels)
    ax.set_xlim(-0.5, len(labels) - 0.2)
    ax.set_ylabel("threshold, Michelson contrast (%; dB = 20 log10 contrast)")
    ax.set_title(f"{title}\nparticipants (grey, 95 % CI), the mean (black, 95 % CI)", fontsize=8)
    mark_simulated(fig, simulated)
    save_figure(fig, out)


if __name__ == "__main__":
    sys.exit(run(main))
