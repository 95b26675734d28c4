"""Ratings (a ``rating`` study, protocols/examples/rating.yaml): the mean rating per condition across participants
with 95 % t intervals (each participant's mean first), the repeated-measures ANOVA of the participants' means
(Greenhouse-Geisser; with 2 or more conditions) and a cumulative-link model of the ratings (ordinal probit,
statsmodels' OrderedModel, with a fixed offset per participant when there are several), all from
psyop.statistics.ratings. The ratings are the trials' ``response_value`` (the point pressed, 1..k).

Writes results/<study>_rating.csv (the condition means), results/<study>_rating_model.csv (the ordinal model's
coefficients and cut points, Wald 95 % intervals; no rows with a single condition), results/<study>.json (the
summary, the ANOVA and the model's flags) and figures/<study>_rating.png (the mean rating per condition; the
share of each scale point per condition).
"""

from __future__ import annotations

import sys

import numpy as np
import pandas as pd
from _common import out_path, parser, provenance, require_columns, require_kind, results_file, run, write_csv, write_json

from psyop.statistics.studies import study_facts

#: the schedule column with the scale's number of points (psyop/protocol/kinds/rating.py)
POINTS_COLUMN = "scale_points"


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "figures/{study}_rating.png", study="rating_realism")
    args = p.parse_args(argv)
    from psyop.statistics.dataset import load_dataset
    from psyop.statistics.ratings import condition_means

    facts = study_facts(args.data, args.study)
    require_kind(facts, "rating", "rating.py")
    ds = load_dataset(args.data, args.study)
    trials = ds.trials
    require_columns(trials, ["participant", "response_value"], str(args.data / args.study),
                    "the trials of a rating session have them; re-run the session with this psyop")
    points, labels = _scale(args.data, args.study, trials)
    trials = trials.assign(rating=trials["response_value"])
    conditions = [name for name in facts.factors if name in trials and trials[name].nunique() > 1]
    means = condition_means(trials, conditions, points=points)
    anova, anova_note = _anova(trials, conditions, points)
    model, model_note, offsets = _model(trials, conditions, points)
    args.results.mkdir(parents=True, exist_ok=True)
    write_csv(means, results_file(args.results, args.study, "rating", "csv"))
    write_csv(_model_table(model), results_file(args.results, args.study, "rating_model", "csv"))
    write_json(results_file(args.results, args.study), {
        **provenance(facts, "rating", args.pool_protocols), "simulated": ds.simulated, "conditions": conditions,
        "points": points, "labels": labels, "ci_level": 0.95,
        "n_participants": int(trials["participant"].nunique()), "n_trials": len(trials),
        "summary": {_label(r, conditions): f"{r['mean']:.3f} [{r['ci_low']:.3f}, {r['ci_high']:.3f}] (n = {r['n']})"
                    + (f" ({r['flags']})" if r["flags"] else "") for r in means.to_dict("records")},
        "anova": None if anova is None else anova.table.to_dict("records"),
        "anova_dropped": None if anova is None else anova.dropped.to_dict("records"),
        "anova_note": anova_note,
        "ordinal_model": None if model is None else {
            "link": model.link, "condition": model.condition, "reference": str(model.reference),
            "participant_offsets": offsets, "converged": model.converged, "log_likelihood": model.log_likelihood,
            "categories_used": list(model.categories_used), "n_trials": model.n_trials,
            "n_participants": model.n_participants, "flags": model.flags, "flag_text": model.flag_text,
            "effects": {r["term"]: f"{r['estimate']:.3f} [{r['ci_low']:.3f}, {r['ci_high']:.3f}] (latent sd units)"
                        for r in model.coefficients.to_dict("records") if not r["term"].startswith("participant=")}},
        "ordinal_model_note": model_note,
    })
    _figure(trials, means, conditions, points, labels, args.study, ds.simulated, out_path(args))
    print(means.to_string(index=False))
    return 0


def _scale(data, study: str, trials: pd.DataFrame) -> tuple[int, list[str] | None]:
    """The scale's points (the trials' column, else the protocol's) and labels (the protocol's, if it has them)."""
    from psyop.datacontract import SESSION_METADATA_FILE
    from psyop.errors import UserError
    from psyop.session.log.record import design_of_record, read_record_file
    from psyop.statistics.dataset import session_files

    scale = None  # the first session's recorded scale (session.json study_design; an older session: its protocol)
    for path in session_files(data, study):
        record = read_record_file(path.parent / SESSION_METADATA_FILE)
        scale = design_of_record(record).scale if record is not None else None
        if scale is not None:
            break
    if POINTS_COLUMN in trials and trials[POINTS_COLUMN].notna().any():
        points = int(pd.to_numeric(trials[POINTS_COLUMN]).max())
    elif scale is not None:
        points = scale.points
    else:
        raise UserError(f"no column {POINTS_COLUMN!r} and no response.scale.points in the sessions' protocol: the "
                        "scale's points are unknown; re-run the sessions with this psyop", str(data / study))
    labels = None if scale is None else scale.labels
    return points, list(labels) if labels is not None and len(labels) == points else None


def _label(row: dict, conditions: list[str]) -> str:
    where = ", ".join(f"{c} = {row[c]}" for c in conditions)
    return "mean rating" + (f" ({where})" if where else "")


def _anova(trials: pd.DataFrame, conditions: list[str], points: int):
    """The RM-ANOVA of the participants' mean ratings over the condition factors (one or two; more are crossed
    into one), or None and why not."""
    from psyop.errors import UserError
    from psyop.statistics.conditions import condition_of, with_condition
    from psyop.statistics.ratings import rm_anova

    if not conditions:
        return None, "a single condition: nothing to compare"
    factors = conditions if len(conditions) <= 2 else [condition_of(conditions)]
    try:
        return rm_anova(with_condition(trials, conditions), factors, points), ""
    except UserError as exc:
        return None, f"ANOVA not run: {exc}"


def _model(trials: pd.DataFrame, conditions: list[str], points: int):
    """The ordinal probit model over the (crossed) conditions, with participant offsets when there are several
    participants; or None and why not."""
    from psyop.errors import UserError
    from psyop.statistics.ratings import ordinal_model

    if not conditions:
        return None, "a single condition: no ordinal model of condition effects", False
    offsets = trials["participant"].nunique() > 1
    try:
        return ordinal_model(trials, conditions, points, link="probit", participant_offsets=offsets), "", offsets
    except UserError as exc:
        return None, f"ordinal model not fitted: {exc}", offsets


def _model_table(model) -> pd.DataFrame:
    columns = ["part", "term", "estimate", "se", "z", "p", "ci_low", "ci_high"]
    if model is None:
        return pd.DataFrame(columns=columns)
    cuts = model.thresholds.rename(columns={"cut": "term"}).assign(part="cut_point")
    return pd.concat([model.coefficients.assign(part="coefficient"), cuts], ignore_index=True)[columns]


def _figure(trials, means, conditions, points, labels, study, simulated, out) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from psyop.figures.output import save_figure
    from psyop.figures.study_figures import mark_simulated

    names = [", ".join(str(r[c]) for c in conditions) or "all" for r in means.to_dict("records")]
    x = np.arange(len(means))
    fig, (left, right) = plt.subplots(1, 2, figsize=(11.0, 4.2))
    left.errorbar(x, means["mean"], yerr=[means["mean"] - means["ci_low"], means["ci_high"] - means["mean"]], fmt="o",
                  capsize=3)
    left.set_xticks(x, names, rotation=30 if len(x) > 6 else 0)
    left.set_xlim(-0.5, len(x) - 0.5)
    left.set_xlabel(", ".join(conditions) or "condition")
    left.set_ylabel("mean rating (95 % CI)")
    left.set_ylim(0.5, points + 0.5)
    left.set_yticks(range(1, points + 1), [f"{j} {labels[j - 1]}" if labels else str(j) for j in range(1, points + 1)],
                    fontsize=7 if labels else None)
    share = np.zeros((len(means), points))
    for i, row in enumerate(means.to_dict("records")):
        mask = np.ones(len(trials), dtype=bool)
        for c in conditions:
            mask &= (trials[c] == row[c]).to_numpy()
        ratings = pd.to_numeric(trials.loc[mask, "rating"]).to_numpy(int)
        share[i] = np.bincount(ratings, minlength=points + 1)[1:points + 1] / max(len(ratings), 1)
    bottom = np.zeros(len(means))
    colours = plt.get_cmap("RdYlGn")(np.linspace(0.1, 0.9, points))
    for j in range(points):
        right.bar(x, share[:, j], bottom=bottom, color=colours[j], label=labels[j] if labels else str(j + 1))
        bottom += share[:, j]
    right.set_xticks(x, names, rotation=30 if len(x) > 6 else 0)
    right.set_xlabel(", ".join(conditions) or "condition")
    right.set_ylabel("share of ratings")
    right.set_ylim(0.0, 1.0)
    right.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.0, 0.5), title="rating", title_fontsize=8,
                 reverse=True)
    fig.suptitle(f"Ratings: {study}")
    mark_simulated(fig, simulated)
    save_figure(fig, out)


if __name__ == "__main__":
    sys.exit(run(main))
