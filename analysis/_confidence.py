"""The confidence part of a kind's analysis, for a study whose response asked a confidence rating after the
choice (``response: confidence:``; psyop.statistics.confidence states the statistics).

:func:`confidence_analysis` writes, beside the kind's own outputs:

- results/<study>_confidence.csv: the mean confidence per condition for correct and incorrect answers (the
  participants' means, a 95 % t interval over participants, flags);
- results/<study>_confidence_auroc.csv: each participant's type-2 ROC area (confidence telling correct from
  incorrect answers) with DeLong's 95 % interval and flags;
- figures/<study>_confidence.png (and .pdf): mean confidence by condition, correct and incorrect apart; each
  participant's type-2 ROC area with its interval and 0.5 (confidence blind to correctness) marked;

- results/<study>_confidence.json: the summary (the two tables and the participants' mean area with its t
  interval);

and returns that summary. A study without the column (or without a single rating, or with no correct answer to
tell apart: a preference) gets None and no files.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from _common import results_file, write_csv, write_json

from psyop.statistics.confidence import (POINTS, auroc_by_participant, auroc_summary, confidence_means,
                                         has_confidence)


def confidence_analysis(trials: pd.DataFrame, conditions: list[str], study: str, results: Path, figure: Path,
                        simulated: bool) -> dict | None:
    """The confidence outputs of ``trials`` over ``conditions`` (see the module docstring); ``figure`` is the
    kind's own figure, the confidence figure is written beside it."""
    if not has_confidence(trials) or "correct" not in trials or not trials["correct"].notna().any():
        return None
    means = confidence_means(trials, conditions)
    per_participant = auroc_by_participant(trials)
    summary = auroc_summary(per_participant)
    write_csv(means, results_file(results, study, "confidence", "csv"))
    write_csv(per_participant, results_file(results, study, "confidence_auroc", "csv"))
    points = int(pd.to_numeric(trials[POINTS]).max()) if POINTS in trials else int(trials["confidence"].max())
    out = figure.with_name(f"{study}_confidence.png")
    _figure(means, per_participant, conditions, points, study, simulated, out)
    payload = {"study": study, "simulated": simulated, "points": points, "conditions": conditions,
               "means": means.to_dict("records"), "type2_auroc": per_participant.to_dict("records"),
               "type2_auroc_mean": summary.to_dict("records")[0],
               "note": "type-2 ROC area per participant over all their rated trials (DeLong 95 % interval); 0.5: "
                       "confidence blind to correctness"}
    write_json(results_file(results, study, "confidence"), payload)
    return payload


def _figure(means: pd.DataFrame, per_participant: pd.DataFrame, conditions: list[str], points: int, study: str,
            simulated: bool, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from psyop.figures.output import save_figure
    from psyop.figures.study_figures import mark_simulated

    # the conditions in t_summary's order (sorted by the condition columns)
    names = list(dict.fromkeys(", ".join(str(r[c]) for c in conditions) or "all" for r in means.to_dict("records")))
    where = {name: i for i, name in enumerate(names)}
    fig, (left, right) = plt.subplots(1, 2, figsize=(11.0, 4.2))
    for correct, colour, shift in ((True, "tab:green", -0.08), (False, "tab:red", 0.08)):
        part = means[means["correct"] == correct]
        x = np.array([where[", ".join(str(r[c]) for c in conditions) or "all"] for r in part.to_dict("records")])
        y = part["mean"].to_numpy(float)
        err = [y - part["ci_low"].to_numpy(float), part["ci_high"].to_numpy(float) - y]
        left.errorbar(x + shift, y, yerr=err, fmt="o-" if conditions else "o", color=colour, capsize=3,
                      label="correct" if correct else "incorrect")
    left.set_xticks(range(len(names)), names, rotation=30 if len(names) > 6 else 0)
    left.set_xlabel(", ".join(conditions) or "condition")
    left.set_ylabel("mean confidence (95 % CI)")
    left.set_ylim(0.5, points + 0.5)
    left.legend(fontsize=8)
    x = np.arange(len(per_participant))
    auroc = per_participant["auroc"].to_numpy(float)
    right.errorbar(x, auroc, yerr=[auroc - per_participant["ci_low"].to_numpy(float),
                                   per_participant["ci_high"].to_numpy(float) - auroc], fmt="o", capsize=3)
    right.axhline(0.5, color="grey", linestyle="--", linewidth=1)
    right.set_xticks(x, per_participant["participant"].astype(str), rotation=90 if len(x) > 10 else 0, fontsize=7)
    right.set_ylim(0.0, 1.0)
    right.set_xlabel("participant")
    right.set_ylabel("type-2 ROC area (95 % CI)")
    fig.suptitle(f"Confidence: {study}")
    mark_simulated(fig, simulated)
    save_figure(fig, out)

