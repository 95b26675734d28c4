"""Thresholds by condition (subject thresholds with 95 % CIs, mean ± SE): the paper's detection
figure, and the thresholds figure of any two-interval study.

Reads the fit cache (results/<study>_fits.csv); writes results/<study>_thresholds.json with the
grand mean threshold (and its 95 % t-interval over participants) and a one-way rm-ANOVA of
thresholds over the condition. Censored thresholds (below the lowest / above the highest level, lapse
at bound) are not dropped from the group estimate: a censored-normal (Tobit) mean enters them at their
bounds (psyop.statistics.censored), and the rm-ANOVA is repeated with them substituted by their bounds
(the sensitivity). The plain mean and rm-ANOVA use the usable fits only
(psyop.statistics.psychometric.usable_for_analysis); every fit left out is counted by status. Axis labels come from
the protocol's factor names, descriptions and units.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from _common import out_path, parser, provenance, read_fits, require_columns, results_file, run, write_json
import fit_psychometric
from _twoafc import check_two_interval, condition_column, condition_facts, level_column

from psyop.figures.output import save_figure
from psyop.figures.study_figures import caption, plot_thresholds
from psyop.statistics.anova import rm_anova
from psyop.statistics.censored import censored_report, censoring_of, fit_fates, substituted
from psyop.statistics.dataset import is_simulated
from psyop.statistics.formatting import format_anova
from psyop.statistics.psychometric import interval_report, usable_for_analysis
from psyop.statistics.small_sample import low_df_note
from psyop.statistics.studies import study_facts
from scipy import stats


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "figures/{study}_thresholds.png", study="detection")
    p.add_argument("--fits", type=Path, default=None, help="fit cache (default results/<study>_fits.csv)")
    p.add_argument("--condition-column", default=None, help="default: the fit cache's (the protocol's condition factor)")
    p.add_argument("--level-column", default=None, help="default: the response's level_factor")
    args = p.parse_args(argv)
    facts = study_facts(args.data, args.study)
    check_two_interval(facts, "fig_detection_thresholds.py")
    fits_path = args.fits or results_file(args.results, args.study, "fits", "csv")
    # a cache given by --fits is the user's: never rebuilt; the default one is rebuilt if unreadable
    fits = read_fits(fits_path) if args.fits else read_fits(fits_path, data=args.data, study=args.study,
                                                                  rebuild=fit_psychometric.main)
    cached = fits["condition_column"].iloc[0] if "condition_column" in fits and len(fits) else None
    cond = condition_column(facts, args.condition_column or cached)
    require_columns(fits, [cond, "threshold_D", "participant"], str(fits_path),
                    "give --condition-column naming the column the fits were made over, or refit with "
                    "analysis/fit_psychometric.py")
    level = facts.factor(level_column(facts, args.level_column))
    unit = level.unit or ""
    simulated = is_simulated(args.data)
    clean, left_out = usable_for_analysis(fits)
    per_subject = clean.groupby("participant")["threshold_D"].mean()
    per_cond = clean.groupby(cond)["threshold_D"].agg(["mean", "std", "count"]).reset_index()
    n = len(per_subject)
    half = float(stats.t.ppf(0.975, n - 1) * per_subject.std(ddof=1) / n ** 0.5) if n > 1 else float("nan")
    mean = float(per_subject.mean()) if n else float("nan")
    everyone = sorted(fits["participant"].astype(str).unique())
    without = [s for s in everyone if s not in set(per_subject.index.astype(str))]
    who = f"{n} of {len(everyone)} participants" + (f" (no usable fit: {', '.join(without)})" if without else "")
    mean_note = low_df_note(float(n - 1), "participant") if n > 1 else ""
    mean_note = f" [{mean_note.replace('p-value', 'interval')}]" if mean_note else ""
    cond_label = condition_facts(facts, cond).label
    key_mean = ("detection threshold (mean over subjects and back distances)" if cond == "back_D"
                else f"{args.study} threshold (mean over subjects and {cond_label})")
    payload = {
        **provenance(facts, "thresholds", args.pool_protocols), "simulated": simulated, "n_subjects": int(fits["participant"].nunique()),
        "condition_column": cond, "level_column": level.name, "level_unit": level.unit,
        "n_fits": len(fits), "n_left_out": int(sum(left_out.values())), "left_out_by_status": left_out,
        "left_out": fits.loc[~fits.index.isin(clean.index), ["participant", cond, "status"]].to_dict("records"),
        "mean_threshold_D": mean, "mean_threshold_ci_D": [mean - half, mean + half],
        "per_condition": per_cond.to_dict("records"),
        "summary": {key_mean:
                    f"{mean:.2f} {unit} [95 % CI {mean - half:.2f}, {mean + half:.2f}; t on {n - 1} df; {who}; "
                    f"{sum(left_out.values())} of {len(fits)} fits left out: {left_out or 'none'}]{mean_note}",
                    "fit intervals": interval_report(fits)["text"]},
        "fit_intervals": interval_report(fits),
        "fits": fit_fates(fits, cond),
    }
    _add_reported(payload, clean, facts.reported, unit)
    effect_key = ("effect of back distance on threshold (rm-ANOVA)" if cond == "back_D"
                  else f"effect of {cond_label} on threshold (rm-ANOVA)")
    if fits[cond].nunique() < 2:  # the level is the only factor (or one condition was run): no effect to test
        payload["summary"][effect_key] = f"not applicable: one condition ({fits[cond].iloc[0]!s}), no effect to test"
        aov = None
    else:
        try:
            aov = rm_anova(clean, "threshold_D", cond)
        except ValueError as exc:  # too few complete subjects: say so instead of a number
            payload["summary"][effect_key] = f"not computed: {exc}"
            aov = None
    if aov is not None:
        payload[f"anova_{cond}"] = aov.table.to_dict("records")
        payload["anova_dropped"] = aov.dropped.to_dict("records")
        payload["summary"][effect_key] = format_anova(aov.table.iloc[0]) + _dropped_text(aov.dropped)
    _add_censored(payload, fits, cond, unit, effect_key)
    payload["group_model"] = _group_model(payload["censored"], n)
    write_json(results_file(args.results, args.study, "thresholds"), payload)
    title = "Detection thresholds" if args.study == "detection" else f"Thresholds: {args.study}"
    fig = plot_thresholds(fits, cond, cond_label, title, simulated=simulated, level_unit=unit or "level units")
    caption(fig, _caption(payload["group_model"]))
    save_figure(fig, out_path(args))
    _confidence(args, cond, level.name, simulated)
    return 0


def _confidence(args, cond: str, level: str, simulated: bool) -> None:
    """A study that asked a confidence rating after each choice: its confidence per condition and level and its
    type-2 ROC areas beside the thresholds (analysis/_confidence.py); nothing for a study without one."""
    from _confidence import confidence_analysis
    from psyop.statistics.dataset import load_dataset

    trials = load_dataset(args.data, args.study).trials
    conditions = [c for c in dict.fromkeys((cond, level)) if c in trials and trials[c].nunique() > 1]
    confidence_analysis(trials, conditions, args.study, args.results, out_path(args), simulated)


def _dropped_text(dropped) -> str:
    """'; participants left out of this rm-ANOVA (no usable fit in every condition): S04' or ''."""
    if not len(dropped):
        return ""
    return ("; participants left out of this rm-ANOVA (no usable fit in every condition): "
            + ", ".join(map(str, dropped["subject"])))


def _group_model(report: dict, n_usable: int) -> dict:
    """The model behind the group estimate that was actually fitted: the censored-data (Tobit) mean, or,
    where it could not be fitted, its fallback (the t-interval over participants' usable fits)."""
    mean = report.get("mean")
    if mean is not None:
        flags = ["low_df"] if mean["low_df"] else []
        name = ("censored-normal (Tobit) ML mean, " + (f"participant-clustered SEs, t on {mean['df_interval']} df"
                if mean["n_clusters"] else f"fits independent, t on {mean['df_interval']} df"))
        return {"name": name, "fallback": False, "flags": flags, "model": mean["model"]}
    return {"name": f"t-interval over the participants' usable fits (t on {n_usable - 1} df)", "fallback": True,
            "flags": ["censored_fits_left_out"] + (["low_df"] if n_usable - 1 < 4 else []),
            "model": f"fallback: the censored-data model was {report['text_mean']}"}


def _caption(model: dict) -> str:
    """The figure's caption: what the black squares are and the group model actually fitted."""
    flags = f" [FLAGGED: {', '.join(model['flags'])}]" if model["flags"] else ""
    return ("Grey: participants' thresholds, 95 % CIs; open triangles: censored fits at their bound.\n"
            "Black: mean ± SE of the usable fits. Group estimate (results/summary.md):\n"
            f"{model['name']}{' (FALLBACK)' if model['fallback'] else ''}{flags}.")


def _add_censored(payload: dict, fits, cond: str, unit: str, effect_key: str) -> None:
    """The censored-data mean and the bound-substitution rm-ANOVA, beside the usable-only ones."""
    report = censored_report(fits, cond, unit)
    payload["censored"] = report
    payload["summary"]["censored thresholds"] = report["headline"]
    payload["summary"]["mean threshold, censored-data model (Tobit)"] = report["text_mean"]
    key = f"{effect_key}, censored fits at their bounds (sensitivity)"
    if not (report["n_censored_below"] + report["n_censored_above"]):
        payload["summary"][key] = "same as above: no censored fits"
        return
    if fits[cond].nunique() < 2:
        payload["summary"][key] = "not applicable: one condition"
        return
    rows, _ = censoring_of(fits)
    try:
        aov = rm_anova(substituted(rows), "threshold_D", cond)
    except ValueError as exc:
        payload["summary"][key] = f"not computed: {exc}"
    else:
        payload["anova_censored_at_bounds"] = aov.table.to_dict("records")
        payload["summary"][key] = format_anova(aov.table.iloc[0])


def _add_reported(payload: dict, clean, reported, unit: str) -> None:
    """Each threshold the protocol's ``study.reported`` gives (a condition: factor -> level, its threshold, its source),
    beside the mean threshold measured there over participants with its 95 % t interval, and whether the reported
    value lies inside it."""
    from psyop.protocol.base import format_level

    rows = []
    for entry in reported:
        condition = {str(k): v for k, v in dict(entry["condition"]).items()}
        mask = np.ones(len(clean), dtype=bool)
        for name, level in condition.items():
            mask &= clean[name].map(format_level).to_numpy() == format_level(level) if name in clean else False
        values = clean.loc[mask].groupby("participant")["threshold_D"].mean()
        n = len(values)
        mean = float(values.mean()) if n else float("nan")
        half = float(stats.t.ppf(0.975, n - 1) * values.std(ddof=1) / n ** 0.5) if n > 1 else float("nan")
        threshold = float(entry["threshold"])
        inside = bool(mean - half <= threshold <= mean + half) if n > 1 else None
        where = ", ".join(f"{k} = {format_level(v)}" for k, v in condition.items())
        source = f" ({entry['source']})" if entry.get("source") else ""
        rows.append({"condition": condition, "threshold": threshold, "source": entry.get("source"), "n": n,
                     "measured_mean": mean, "measured_ci": [mean - half, mean + half], "inside_ci": inside})
        payload["summary"][f"reported threshold at {where}{source}"] = (
            f"{threshold:g} {unit}; measured {mean:.2f} {unit} [95 % CI {mean - half:.2f}, {mean + half:.2f}; "
            f"{n} participants]: " + ("inside the interval" if inside else "outside the interval" if inside is False
                                      else "no interval (fewer than 2 participants)"))
    if rows:
        payload["reported"] = rows


if __name__ == "__main__":
    sys.exit(run(main))
