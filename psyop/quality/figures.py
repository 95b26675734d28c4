"""The gaze-quality figures a researcher looks at first: each ruled (or headline) measure per participant
with the rule's threshold drawn, and the raw gaze of sample trials over time against the target."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from psyop.protocol.quality import QualityRule, QualitySection
from psyop.quality.target import target_path_deg
from psyop.session.plan import SessionPlan

HEADLINE = ("data_loss_share", "accuracy_fixation_mean_deg", "precision_rms_s2s_deg", "pursuit_gain")


def _thresholds(rules: QualitySection | None, measure: str) -> list[tuple[float, str]]:
    if rules is None:
        return []
    out = [(_bound(r), "trial rule") for r in rules.trials if r.measure == measure]
    return out + [(_bound(r), "participant median rule") for r in rules.participants if r.measure == measure]


def _bound(rule: QualityRule) -> float:
    """The rule's threshold: its max: or its min: (validation requires exactly one)."""
    bound = rule.max if rule.max is not None else rule.min
    assert bound is not None
    return bound


def plot_measures(measures: pd.DataFrame, rules: QualitySection | None, study: str):
    """One panel per measure (the ruled ones, then :data:`HEADLINE`): each trial's value per participant,
    the participant's median as a bar, each rule's threshold as a dashed line. A measure with no finite
    value says so in its panel (not measurable from this stream)."""
    ruled = [r.measure for r in [*(rules.trials if rules else []), *(rules.participants if rules else [])]]
    names = list(dict.fromkeys([*ruled, *HEADLINE]))
    people = sorted(measures["participant"].astype(str).unique()) if not measures.empty else []
    fig, axes = plt.subplots(1, len(names), figsize=(3.2 * len(names), 3.0), squeeze=False)
    for ax, name in zip(axes[0], names):
        for i, who in enumerate(people):
            values = measures.loc[measures["participant"].astype(str) == who, name].to_numpy(dtype=float)
            values = values[np.isfinite(values)]
            ax.plot(np.full(len(values), i) + np.linspace(-0.2, 0.2, len(values)), values, ".", ms=3, alpha=0.5)
            if len(values):
                ax.hlines(np.median(values), i - 0.3, i + 0.3, color="k")
        for value, label in _thresholds(rules, name):
            ax.axhline(value, ls="--", color="r", label=label)
        if not np.isfinite(measures[name].to_numpy(dtype=float)).any() if not measures.empty else True:
            ax.text(0.5, 0.5, "not measurable\nfrom this stream", transform=ax.transAxes, ha="center", va="center")
        ax.set_xticks(range(len(people)), people, rotation=90, fontsize=6)
        ax.set_title(name, fontsize=8)
        if _thresholds(rules, name):
            ax.legend(fontsize=6)
    fig.suptitle(f"{study}: gaze quality per trial (dots), participant median (bar), rule thresholds (dashed)", fontsize=9)
    fig.tight_layout()
    return fig


#: the step (s) at which the sample figure draws the target's path
TARGET_STEP_S = 0.001


def plot_sample_trials(gaze: pd.DataFrame, trials: pd.DataFrame, plan: SessionPlan | None = None,
                       n_trials: int = 3):
    """Raw gaze azimuth and elevation (deg, Fick) over the first ``n_trials`` trials of one session, with the
    trial boundaries; only valid samples are drawn (each as recorded, not on a grid). With the session's
    ``plan``, the target the gaze is measured against (:func:`psyop.quality.target.target_path_deg`: the
    cross, the pursuit path) is drawn dashed every :data:`TARGET_STEP_S` (gaps: phases without a target)."""
    from psyop.quality.samples import _angles

    fig, ax = plt.subplots(figsize=(9, 3))
    rows = trials.head(n_trials)
    if len(rows):
        start, end = float(rows["trial_start_s"].min()), float(rows["trial_end_s"].max())
        if len(gaze):
            t = gaze["gaze_sample_t_s"].to_numpy(dtype=float)
            az, el = _angles(*(gaze[f"fixation_{a}_m"].to_numpy(dtype=float) for a in "xyz"))
            ok = (t >= start) & (t <= end) & gaze["gaze_valid"].to_numpy(dtype=bool)
            ax.plot(t[ok] - start, az[ok], ".-", ms=3, lw=0.5, color="C0", label="azimuth (deg)")
            ax.plot(t[ok] - start, el[ok], ".-", ms=3, lw=0.5, color="C1", label="elevation (deg)")
        if plan is not None:
            t_target = start + np.arange(int(np.ceil((end - start) / TARGET_STEP_S))) * TARGET_STEP_S
            target = target_path_deg(plan, rows, t_target)
            ax.plot(t_target - start, target[:, 0], "--", lw=1.0, color="C0", alpha=0.8, label="target azimuth (deg)")
            ax.plot(t_target - start, target[:, 1], "--", lw=1.0, color="C1", alpha=0.8, label="target elevation (deg)")
        for trial_start_s in rows["trial_start_s"]:
            ax.axvline(float(trial_start_s) - start, color="0.7", lw=0.5)
    ax.set_xlabel("time from the first trial's start (s)")
    ax.set_ylabel("gaze (deg)")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))  # beside the traces, not over them
    fig.tight_layout()
    return fig
