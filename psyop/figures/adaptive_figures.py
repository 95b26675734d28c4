"""Staircase / QUEST+ track plots: level by trial per participant (rows) x condition (columns),
reversals marked, the procedure's final estimate with its 95 % interval and the fit's threshold."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.lines import Line2D

from psyop.figures.labels import STYLE, condition_label, participant_label
from psyop.figures.study_figures import mark_simulated


def _track_panel(ax, g: pd.DataFrame, row, level: str, est: str, sd: str) -> None:
    x = g["trial_in_track"].to_numpy()
    ax.plot(x, g[level], "-", color="0.6", lw=0.8, zorder=1)
    correct = g["correct"].fillna(False).astype(bool).to_numpy() if "correct" in g else np.ones(len(g), bool)
    ax.plot(x[correct], g[level].to_numpy()[correct], "o", ms=3, color="k", zorder=2)
    ax.plot(x[~correct], g[level].to_numpy()[~correct], "o", ms=3, mfc="white", color="k", zorder=2)
    rev = g["is_reversal"].to_numpy()
    ax.plot(x[rev], g[level].to_numpy()[rev], "D", ms=6, mfc="none", mec="#ff7f0e", zorder=3)
    e, s = float(g.iloc[-1][est]), float(g.iloc[-1][sd])
    if np.isfinite(e):
        ax.axhline(e, color="#1f77b4", lw=1.2)
        if np.isfinite(s):
            ax.axhspan(e - 1.96 * s, e + 1.96 * s, color="#1f77b4", alpha=0.15, lw=0)
    if row is not None and np.isfinite(row.get("fit_threshold_D", np.nan)):
        ax.axhline(row["fit_threshold_D"], color="#d62728", lw=1, ls="--")
    elif row is not None and isinstance(row.get("fit_status"), str) and row["fit_status"] != "ok":
        ax.text(0.97, 0.95, f"fit: {row['fit_status'].replace('_', ' ')}", transform=ax.transAxes, ha="right",
                va="top", fontsize=8, color="#b00020")


def plot_tracks(tracks: pd.DataFrame, table: pd.DataFrame, condition: str, level: str, unit: str,
                title: str, simulated: bool = False) -> plt.Figure:
    """``tracks`` from :func:`psyop.statistics.adaptive_estimates.mark_reversals`; ``table`` from
    :func:`~psyop.statistics.adaptive_estimates.estimates_table` (its fit columns draw the fit line)."""
    est, sd = f"adaptive_estimate_{unit}", f"adaptive_estimate_sd_{unit}"
    subjects, conds = sorted(tracks["participant"].unique()), sorted(tracks[condition].unique())
    row_of = {(r["participant"], r[condition]): r for _, r in table.iterrows()}
    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(len(subjects), len(conds), figsize=(3.0 * len(conds), 1.9 * len(subjects) + 0.9),
                                 squeeze=False, sharey=True)
        for (s, c), g in tracks.groupby(["participant", condition], sort=False):
            ax = axes[subjects.index(s), conds.index(c)]
            _track_panel(ax, g, row_of.get((s, c)), level, est, sd)
        for j, c in enumerate(conds):
            axes[0, j].set_title(condition_label(condition, c))
            axes[-1, j].set_xlabel("trial")
        for i, s in enumerate(subjects):
            axes[i, 0].set_ylabel(f"{participant_label(s)}\nlevel ({unit})")
        handles = [Line2D([], [], color="k", marker="o", ls="", ms=3, label="correct"),
                   Line2D([], [], color="k", marker="o", mfc="white", ls="", ms=3, label="wrong"),
                   Line2D([], [], color="#ff7f0e", marker="D", mfc="none", ls="", label="reversal"),
                   Line2D([], [], color="#1f77b4", label="procedure estimate, 95 % interval"),
                   Line2D([], [], color="#d62728", ls="--", label="psychometric fit threshold")]
        fig.suptitle(title)
        fig.tight_layout(rect=(0, 0.05, 1, 0.97))
        fig.legend(handles=handles, loc="lower center", ncol=5, frameon=False, bbox_to_anchor=(0.5, 0.0))
        mark_simulated(fig, simulated)
    return fig


__all__ = ["plot_tracks"]
