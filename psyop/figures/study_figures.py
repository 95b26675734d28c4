"""Drawing code for the paper's study figures. Takes statistics tables, returns matplotlib figures.

No file reading here: ``analysis/`` scripts load data, call :mod:`psyop.statistics`, and pass
the tidy tables in. :func:`psyop.figures.output.save_figure` writes the PNG and a PDF beside it.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from psyop.statistics.psychometric import predicted_pc

MODE_COLOURS = {"conventional": "#7f7f7f", "ocular": "#1f77b4", "reversed": "#ff7f0e",
                "enabled": "#1f77b4", "disabled": "#7f7f7f"}
SIMULATED_LABEL = "SIMULATED DATA"


def mark_simulated(fig: plt.Figure, simulated: bool) -> None:
    """Say so above the title and in it when the data came from simulated sessions."""
    if not simulated:
        return
    fig.text(0.5, 1.0, SIMULATED_LABEL, ha="center", va="bottom", fontsize=8, color="#b00020",  # the tight bbox grows to fit
             fontweight="bold", alpha=0.9)
    title = fig._suptitle.get_text() if fig._suptitle is not None else ""
    fig.suptitle(f"{title} ({SIMULATED_LABEL.lower()})" if title else SIMULATED_LABEL.lower(), fontsize=10)


def _sem(values: pd.Series) -> float:
    v = values.dropna()
    return float(v.std(ddof=1) / np.sqrt(len(v))) if len(v) > 1 else float("nan")


def plot_thresholds(fits: pd.DataFrame, condition_column: str, xlabel: str, title: str,
                    line: tuple[float, float] | None = None, simulated: bool = False) -> plt.Figure:
    """Per-subject thresholds with 95 % CIs (small, jittered) and the subject mean +- SE.

    ``line`` = (slope, intercept) draws the linear fit (discrimination). Flagged fits are
    drawn hollow and left out of the mean.
    """
    fig, ax = plt.subplots(figsize=(4.2, 3.4))
    conds = sorted(fits[condition_column].unique())
    subjects = sorted(fits["participant"].unique())
    jitter = dict(zip(subjects, np.linspace(-0.12, 0.12, max(len(subjects), 1))))
    for _, r in fits.iterrows():
        x = r[condition_column] + jitter[r["participant"]]
        clean = not r["flags"] if isinstance(r["flags"], str) else True
        ax.errorbar(x, r["threshold_D"], yerr=[[r["threshold_D"] - r["threshold_ci_low_D"]],
                                               [r["threshold_ci_high_D"] - r["threshold_D"]]],
                    fmt="o", ms=3, color="#999999", mfc="#999999" if clean else "white", lw=0.8, zorder=1)
    ok = fits[fits["flags"].fillna("") == ""] if "flags" in fits else fits
    means = ok.groupby(condition_column)["threshold_D"].agg(["mean", _sem]).reindex(conds)
    ax.errorbar(conds, means["mean"], yerr=means["_sem"], fmt="s-", color="k", ms=6, capsize=4, lw=1.5,
                zorder=3, label="mean +- SE")
    if line is not None:
        xs = np.linspace(min(conds) - 0.2, max(conds) + 0.2, 50)
        ax.plot(xs, line[1] + line[0] * xs, "--", color="#1f77b4", lw=1.2,
                label=f"fit: {line[0]:.2f} x + {line[1]:.2f} D", zorder=2)
    ax.set_xticks(conds)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("threshold (D)")
    ax.set_ylim(bottom=min(0.0, ax.get_ylim()[0]))
    ax.legend(fontsize=7, loc="upper left", frameon=False)
    fig.suptitle(title, fontsize=10)
    mark_simulated(fig, simulated)
    return fig


def plot_psychometric_grid(blocks: pd.DataFrame, fits: pd.DataFrame, condition_column: str,
                           title: str, simulated: bool = False) -> plt.Figure:
    """Every subject (rows) x condition (columns): proportion correct, fitted curve, threshold and CI.

    ``blocks`` has participant, condition, ``level_D``, ``n_correct``, ``n_total``.
    """
    subjects = sorted(fits["participant"].unique())
    conds = sorted(fits[condition_column].unique())
    fig, axes = plt.subplots(len(subjects), len(conds), figsize=(2.3 * len(conds), 1.6 * len(subjects)),
                             sharey=True, squeeze=False)
    for i, s in enumerate(subjects):
        for j, c in enumerate(conds):
            ax = axes[i, j]
            b = blocks[(blocks["participant"] == s) & (blocks[condition_column] == c)]
            f = fits[(fits["participant"] == s) & (fits[condition_column] == c)]
            ax.plot(b["level_D"], b["n_correct"] / b["n_total"], "o", ms=3, color="k")
            if not f.empty and np.isfinite(f["threshold_D"].iloc[0]):
                r = f.iloc[0]
                xs = np.linspace(r["level_min_D"], r["level_max_D"], 100)
                ax.plot(xs, predicted_pc(xs, r["location_D"], r["width_D"], r["lapse"]), color="#1f77b4", lw=1)
                ax.plot([r["threshold_D"]] * 2, [0.5, 0.75], color="#d62728", lw=0.8)
                ax.plot([r["threshold_ci_low_D"], r["threshold_ci_high_D"]], [0.75, 0.75], color="#d62728", lw=0.8)
                if r["flags"]:
                    ax.text(0.02, 0.95, r["flags"], transform=ax.transAxes, fontsize=5, va="top", color="#b00020")
            ax.set_ylim(0.0, 1.02)  # below-chance points must stay visible
            ax.tick_params(labelsize=6)
            if i == 0:
                ax.set_title(f"{condition_column} = {c:g}", fontsize=7)
            if j == 0:
                ax.set_ylabel(f"sub-{s}\nP(correct)", fontsize=6)
            if i == len(subjects) - 1:
                ax.set_xlabel("level (D)", fontsize=6)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    mark_simulated(fig, simulated)
    return fig


def plot_ordinal(cells: pd.DataFrame, posthoc: pd.DataFrame, dv: str = "correct",
                 simulated: bool = False) -> plt.Figure:
    """Proportion correct by mode at each separation: subject means +- SE and Bonferroni stars."""
    fig, ax = plt.subplots(figsize=(4.4, 3.4))
    seps = sorted(cells["separation_D"].unique())
    modes = [m for m in ("conventional", "ocular", "reversed") if m in set(cells["mode"])]
    width = 0.8 / len(modes)
    summary = cells.groupby(["separation_D", "mode"])[dv].agg(["mean", _sem])
    top = 0.0
    xpos = {}
    for k, mode in enumerate(modes):
        xs = np.arange(len(seps)) + (k - (len(modes) - 1) / 2) * width
        m = [summary.loc[(s, mode), "mean"] for s in seps]
        e = [summary.loc[(s, mode), "_sem"] for s in seps]
        ax.bar(xs, m, width * 0.95, yerr=e, capsize=3, color=MODE_COLOURS.get(mode), label=mode)
        top = max(top, max(np.add(m, e)))
        for s, x in zip(seps, xs):
            xpos[(s, mode)] = x
    level = top + 0.03
    for s in seps:
        rows = posthoc[(posthoc["separation_D"] == s) & (posthoc["stars"] != "")]
        for n, (_, r) in enumerate(rows.iterrows()):
            x0, x1 = xpos[(s, r["A"])], xpos[(s, r["B"])]
            y = level + 0.05 * n
            ax.plot([x0, x0, x1, x1], [y - 0.01, y, y, y - 0.01], color="k", lw=0.8)
            ax.text((x0 + x1) / 2, y, r["stars"], ha="center", va="bottom", fontsize=8)
    ax.axhline(0.5, color="k", ls=":", lw=0.8)
    ax.set_xticks(range(len(seps)), [f"{s:g} D" for s in seps])
    ax.set_xlabel("separation")
    ax.set_ylabel("proportion correct")
    ax.set_ylim(0.0, max(1.0, level + 0.2))
    ax.legend(fontsize=7, frameon=False, loc="upper left", ncol=3)
    fig.suptitle("Ordinal depth", fontsize=10)
    mark_simulated(fig, simulated)
    return fig


def plot_reach(reaches: pd.DataFrame, lines: pd.DataFrame, x: str = "target_fraction", y: str = "reach_fraction",
               condition: str = "rendering", simulated: bool = False) -> plt.Figure:
    """Reach against target (fractions of arm reach) per condition, with each condition's line."""
    fig, ax = plt.subplots(figsize=(4.2, 3.6))
    for k, (cond, sub) in enumerate(sorted(reaches.groupby(condition), key=lambda t: str(t[0]))):
        colour = MODE_COLOURS.get(cond, f"C{k}")
        per = sub.groupby(["participant", x])[y].mean().reset_index()
        dx = (k - 0.5) * 0.008
        ax.plot(per[x] + dx, per[y], "o", ms=2.5, alpha=0.5, color=colour)
        r = lines[lines[condition] == cond].iloc[0]
        xs = np.linspace(reaches[x].min() - 0.03, reaches[x].max() + 0.03, 20)
        ax.plot(xs, r["intercept"] + r["slope"] * xs, color=colour, lw=1.5,
                label=f"{cond}: {r['slope']:.3f} x + {r['intercept']:.3f}")
    lim = [0.4, max(1.3, float(reaches[y].max()) + 0.05)]
    ax.plot(lim, lim, "k:", lw=0.8, label="veridical")
    ax.set_xlabel("target distance (fraction of arm reach)")
    ax.set_ylabel("reach (fraction of arm reach)")
    ax.legend(fontsize=7, frameon=False, loc="upper left")
    fig.suptitle("Egocentric blind reaching", fontsize=10)
    mark_simulated(fig, simulated)
    return fig


def plot_preferences(prefs: pd.DataFrame, simulated: bool = False) -> plt.Figure:
    """Percent of trials the first mode of each pair was chosen, SE across subjects, stars."""
    fig, ax = plt.subplots(figsize=(4.2, 3.4))
    labels = [f"{a}\nover {b}" for a, b in zip(prefs["first"], prefs["second"])]
    xs = np.arange(len(prefs))
    se = prefs["se_subjects"].fillna(prefs["se"]) * 100
    ax.bar(xs, prefs["proportion"] * 100, yerr=se, capsize=4, color=[MODE_COLOURS.get(m, "C0") for m in prefs["first"]])
    for x, p, e, s in zip(xs, prefs["proportion"] * 100, se, prefs["stars"]):
        ax.text(x, p + e + 1.5, s, ha="center", fontsize=9)
    ax.axhline(50, color="k", ls=":", lw=0.8)
    ax.set_xticks(xs, labels, fontsize=7)
    ax.set_ylabel("% of trials chosen")
    ax.set_ylim(0, 100)
    fig.suptitle("Perceptual realism (pairwise preference)", fontsize=10)
    mark_simulated(fig, simulated)
    return fig
