"""Drawing code for the paper's study figures. Takes statistics tables, returns matplotlib figures.

No file reading here: ``analysis/`` scripts load data, call :mod:`psyop.statistics`, and pass
the tidy tables in. :func:`psyop.figures.output.save_figure` writes the PNG and a PDF beside it.

Rules every figure follows (docs/statistics.md, "Figures"): readable condition names
(:mod:`psyop.figures.labels`), the error-bar type in a legend or the caption line, every
colour in a legend, text >= 9 pt at the saved size (:data:`STYLE`), confidence intervals
clipped at 0 D with a marker, censored thresholds drawn as bounds, and one "simulated data"
label when the data came from simulated sessions.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.lines import Line2D

from psyop.figures.labels import STYLE, condition_label, mode_label, participant_label
from psyop.statistics.conditions import level_text, numeric_levels
from psyop.statistics.psychometric import USABLE_STATUSES, predicted_pc

MODE_COLOURS = {"conventional": "#7f7f7f", "ocular": "#1f77b4", "reversed": "#ff7f0e",
                "enabled": "#1f77b4", "disabled": "#7f7f7f"}
SIMULATED_LABEL = "simulated data"
SUBJECT_GREY = "#8c8c8c"


def mark_simulated(fig: plt.Figure, simulated: bool) -> None:
    """One label above the title when the data came from simulated sessions."""
    if not simulated:
        return
    fig.text(0.5, 1.0, SIMULATED_LABEL, ha="center", va="bottom", fontsize=10, color="#b00020",  # the tight bbox grows to fit
             fontweight="bold")


def caption(fig: plt.Figure, text: str, y: float = 0.0) -> None:
    """A caption under the axes (error-bar types, tests), >= 9 pt; ``y`` in figure coordinates."""
    fig.text(0.5, y, text, ha="center", va="top", fontsize=9)


def _sem(values: pd.Series) -> float:
    v = values.dropna()
    return float(v.std(ddof=1) / np.sqrt(len(v))) if len(v) > 1 else float("nan")


def _usable(fits: pd.DataFrame) -> pd.Series:
    if "status" in fits:
        return fits["status"].isin(USABLE_STATUSES)
    return fits["flags"].fillna("") == ""


def _draw_participant_thresholds(ax, fits: pd.DataFrame, usable: pd.Series, condition_column: str,
                                 jitter: dict, ymax: float, where: dict) -> tuple[int, int, int]:
    """Each participant's threshold and CI (or censored bound) at its condition's x (``where``);
    returns the counts of clipped CIs, open CIs and censored fits for the legend."""
    n_clipped = n_open = n_censored = 0
    for (_, r), ok in zip(fits.iterrows(), usable):
        x = where[r[condition_column]] + jitter[r["participant"]]
        status = r.get("status", "ok")
        if status in ("censored_below", "censored_above", "lapse_at_bound"):
            below = status == "censored_below"
            ax.plot(x, r["threshold_bound_D"], "v" if below else "^", ms=6, mfc="white", mec="#b00020", zorder=2,
                    clip_on=False)
            n_censored += 1
            continue
        if not np.isfinite(r["threshold_D"]):
            continue
        lo, hi = r["threshold_ci_low_D"], r["threshold_ci_high_D"]
        lo_c = max(lo, 0.0)
        hi_c = hi if np.isfinite(hi) else ymax
        ax.plot([x, x], [lo_c, hi_c], color=SUBJECT_GREY, lw=0.9, zorder=1)
        ax.plot(x, r["threshold_D"], "o", ms=3.5, color=SUBJECT_GREY, mfc=SUBJECT_GREY if ok else "white", zorder=1)
        if lo < 0.0:
            ax.plot(x, 0.0, "v", ms=5, color=SUBJECT_GREY, zorder=1, clip_on=False)
            n_clipped += 1
        if not np.isfinite(hi):
            ax.annotate("", (x, ymax), (x, ymax * 0.93), arrowprops=dict(arrowstyle="->", color=SUBJECT_GREY, lw=0.9))
            n_open += 1
    return n_clipped, n_open, n_censored


def condition_positions(conditions: pd.Series) -> tuple[list, dict, list[str]]:
    """The conditions in order, each one's x and tick label: numbers at their value (``1``, ``2.5``),
    words (or crossed cells) one apart in sorted order, labelled as they are.

    Examples
    --------
    >>> condition_positions(pd.Series([2.0, 1.0, 2.0]))
    ([1.0, 2.0], {1.0: 1.0, 2.0: 2.0}, ['1', '2'])
    >>> condition_positions(pd.Series(["reversed", "ocular"]))
    (['ocular', 'reversed'], {'ocular': 0, 'reversed': 1}, ['ocular', 'reversed'])
    """
    if numeric_levels(conditions):
        numbers = sorted({float(c) for c in conditions})
        return numbers, {c: c for c in numbers}, [level_text(c) for c in numbers]
    words = sorted({str(c) for c in conditions})
    return words, {c: i for i, c in enumerate(words)}, words


def _condition_ticks(fig: plt.Figure, ax: plt.Axes, xs: list[float], ticks: list[str]) -> None:
    """Tick labels at the conditions; a crossed cell's factors one per line ("back_D=1" over "mode=ocular"),
    with room made under the axes for them."""
    lines = [t.replace(", ", "\n") for t in ticks]
    ax.set_xticks(xs, lines)
    extra = max((t.count("\n") for t in lines), default=0)
    if extra:
        fig.subplots_adjust(bottom=0.11 + 0.05 * extra)


def _threshold_handles(n_clipped: int, n_open: int, n_censored: int, level_unit: str) -> list:
    """The legend entries of :func:`plot_thresholds` (markers that were drawn only)."""
    handles = [
        Line2D([], [], color=SUBJECT_GREY, marker="o", ms=4, lw=0.9, label="participant: threshold ± 95 % CI"),
        Line2D([], [], color="k", marker="s", ms=6, lw=1.5, label="mean ± SE across participants (usable fits)"),
    ]
    if n_clipped:
        handles.append(Line2D([], [], color=SUBJECT_GREY, marker="v", ls="", ms=5, label=f"CI clipped at 0 {level_unit}"))
    if n_open:
        handles.append(Line2D([], [], color=SUBJECT_GREY, marker="$\\uparrow$", ls="", ms=7, label="CI without upper bound"))
    if n_censored:
        handles.append(Line2D([], [], color="#b00020", marker="v", mfc="white", ls="", ms=6,
                              label="censored: beyond tested levels (not in the mean; in the Tobit model)"))
    return handles


def plot_thresholds(fits: pd.DataFrame, condition_column: str, xlabel: str, title: str,
                    line: tuple[float, float] | None = None, simulated: bool = False,
                    level_unit: str = "D") -> plt.Figure:
    """Per-participant thresholds with 95 % CIs (grey, jittered) and the mean ± SE across participants.

    CIs are clipped at 0 D (a down-triangle marks a clipped lower bound) and an infinite upper
    bound is drawn as an up-arrow. Censored fits are drawn at their bound as open triangles
    (below the lowest / above the highest level) and, like other unusable fits, left out of the
    mean drawn (the censored-data model of results/summary.md enters them at their bound). ``line`` = (slope, intercept) draws the linear fit (discrimination). ``level_unit``: the
    level factor's unit (thresholds are in it; the fit cache's ``_D`` columns hold that unit).
    """
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(5.0, 4.0))
        conds, where, ticks = condition_positions(fits[condition_column])
        xs_cond = [where[c] for c in conds]
        subjects = sorted(fits["participant"].unique())
        jitter = dict(zip(subjects, np.linspace(-0.15, 0.15, max(len(subjects), 1))))
        usable = _usable(fits)
        top = max([0.0] + [float(v) for v in fits["threshold_ci_high_D"] if np.isfinite(v)]
                  + [float(v) for v in fits.get("threshold_bound_D", pd.Series(dtype=float)) if np.isfinite(v)])
        ymax = max(1.0, top * 1.1)
        n_clipped, n_open, n_censored = _draw_participant_thresholds(ax, fits, usable, condition_column, jitter, ymax,
                                                                     where)
        ok = fits[usable]
        means = ok.groupby(condition_column)["threshold_D"].agg(["mean", _sem]).reindex(conds)
        ax.errorbar(xs_cond, means["mean"], yerr=means["_sem"], fmt="s-", color="k", ms=6, capsize=4, lw=1.5, zorder=3)
        handles = _threshold_handles(n_clipped, n_open, n_censored, level_unit)
        if line is not None:
            xs = np.linspace(min(xs_cond) - 0.2, max(xs_cond) + 0.2, 50)
            ax.plot(xs, line[1] + line[0] * xs, "--", color="#1f77b4", lw=1.2, zorder=2)
            handles.append(Line2D([], [], color="#1f77b4", ls="--", label=f"linear fit: {line[0]:.2f} x + {line[1]:.2f} {level_unit}"))
        _condition_ticks(fig, ax, xs_cond, ticks)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(f"threshold ({level_unit})")
        ax.set_ylim(0.0, ymax)
        ax.legend(handles=handles, loc="upper left", frameon=False)
        ax.set_title(title)
        mark_simulated(fig, simulated)
    return fig


def _psychometric_panel(ax, b: pd.DataFrame, r, level_column: str, n_max: float) -> None:
    """One participant x condition panel: proportion correct per level (marker area proportional to
    the trials at that level when they differ, as adaptive runs place them), the fitted curve, the
    threshold with its CI and a non-ok status."""
    pc = b["n_correct"] / b["n_total"]
    if len(b) and (b["n_total"] != n_max).any():
        ax.scatter(b[level_column], pc, s=16.0 * b["n_total"] / n_max, color="k", zorder=2)
    else:
        ax.plot(b[level_column], pc, "o", ms=4, color="k")
    if r is None:
        return
    if np.isfinite(r["location_D"]):
        xs = np.linspace(r["level_min_D"], r["level_max_D"], 100)
        ax.plot(xs, predicted_pc(xs, r["location_D"], r["width_D"], r["lapse"]), color="#1f77b4", lw=1.2)
    if np.isfinite(r["threshold_D"]):
        hi = r["threshold_ci_high_D"] if np.isfinite(r["threshold_ci_high_D"]) else r["level_max_D"]
        ax.plot([r["threshold_D"]] * 2, [0.5, 0.75], color="#d62728", lw=1)
        ax.plot([max(r["threshold_ci_low_D"], r["level_min_D"]), hi], [0.75, 0.75], color="#d62728", lw=1)
    status = r.get("status", "ok")
    if status != "ok":
        ax.text(0.03, 0.05, status.replace("_", " "), transform=ax.transAxes, fontsize=9,
                va="bottom", color="#b00020")


def plot_psychometric_grid(blocks: pd.DataFrame, fits: pd.DataFrame, condition_column: str,
                           title: str, simulated: bool = False, level_column: str = "level_D",
                           level_label: str = "level (D)") -> plt.Figure:
    """Every participant (rows) x condition (columns): proportion correct, fitted curve, threshold and 95 % CI.

    ``blocks`` has participant, condition, ``level_column``, ``n_correct``, ``n_total``. A fit whose
    status is not 'ok' names its status in the panel; ``level_label`` labels the level axis.
    """
    subjects = sorted(fits["participant"].unique())
    conds = condition_positions(fits[condition_column])[0]
    keys = ["participant", condition_column]
    block_of = {key: b for key, b in blocks.groupby(keys, sort=False)}
    fit_of = {key: f.iloc[0] for key, f in fits.groupby(keys, sort=False)}
    no_blocks = blocks.iloc[:0]
    n_max = float(blocks["n_total"].max()) if len(blocks) else 1.0
    varying = bool(len(blocks)) and bool((blocks["n_total"] != n_max).any())
    with plt.rc_context(STYLE):
        # Not sharey: shared axes make every limit change and every draw visit all the others
        # (quadratic in panels: 7.8 s for set_ylim alone at 180). Every panel gets the same
        # limits instead, and only the first column its y tick labels, as sharey would draw it.
        fig, axes = plt.subplots(len(subjects), len(conds), figsize=(3.0 * len(conds), 2.1 * len(subjects) + 0.8),
                                 squeeze=False)
        for i, s in enumerate(subjects):
            for j, c in enumerate(conds):
                ax = axes[i, j]
                _psychometric_panel(ax, block_of.get((s, c), no_blocks), fit_of.get((s, c)), level_column, n_max)
                ax.set_ylim(0.0, 1.02)  # below-chance points must stay visible
                if j > 0:
                    ax.yaxis.set_tick_params(which="both", labelleft=False)
                    ax.yaxis.offsetText.set_visible(False)
                if i == 0:
                    ax.set_title(condition_label(condition_column, c))
                if j == 0:
                    ax.set_ylabel(f"{participant_label(s)}\nP(correct)")
                if i == len(subjects) - 1:
                    ax.set_xlabel(level_label)
        points = f"proportion correct (marker area: trials, largest {n_max:g})" if varying else "proportion correct"
        handles = [Line2D([], [], color="k", marker="o", ls="", label=points),
                   Line2D([], [], color="#1f77b4", label="fitted function (MAP)"),
                   Line2D([], [], color="#d62728", label="75 % threshold and 95 % CI")]
        fig.suptitle(title)
        fig.tight_layout(rect=(0, 0.04, 1, 0.975))
        fig.legend(handles=handles, loc="lower center", ncol=3, frameon=False, bbox_to_anchor=(0.5, 0.0))
        mark_simulated(fig, simulated)
    return fig


def plot_ordinal(cells: pd.DataFrame, posthoc: pd.DataFrame, dv: str = "correct",
                 simulated: bool = False, separation_column: str = "separation_D",
                 separation_label: str = "separation of the two surfaces", separation_unit: str = "D",
                 title: str = "Ordinal depth") -> plt.Figure:
    """Proportion correct by mode at each separation: mean ± SE across participants; Bonferroni stars.
    ``separation_column``/``separation_label``/``separation_unit``: the protocol's separation factor."""
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(5.2, 4.0))
        seps = sorted(cells[separation_column].unique())
        modes = [m for m in ("conventional", "ocular", "reversed") if m in set(cells["mode"])]
        width = 0.8 / len(modes)
        summary = cells.groupby([separation_column, "mode"])[dv].agg(["mean", _sem])
        top = 0.0
        xpos = {}
        for k, mode in enumerate(modes):
            xs = np.arange(len(seps)) + (k - (len(modes) - 1) / 2) * width
            m = [summary.loc[(s, mode), "mean"] for s in seps]
            e = [summary.loc[(s, mode), "_sem"] for s in seps]
            ax.bar(xs, m, width * 0.95, yerr=e, capsize=3, color=MODE_COLOURS.get(mode), label=mode_label(mode))
            top = max(top, max(np.add(m, e)))
            for s, x in zip(seps, xs):
                xpos[(s, mode)] = x
        level = top + 0.03
        m_family = int(posthoc["m"].iloc[0]) if len(posthoc) else 0
        for s in seps:
            rows = posthoc[(posthoc[separation_column] == s) & (posthoc["stars"] != "")]
            for n, (_, r) in enumerate(rows.iterrows()):
                x0, x1 = xpos[(s, r["A"])], xpos[(s, r["B"])]
                y = level + 0.06 * n
                ax.plot([x0, x0, x1, x1], [y - 0.01, y, y, y - 0.01], color="k", lw=0.8)
                ax.text((x0 + x1) / 2, y, r["stars"], ha="center", va="bottom", fontsize=10)
        ax.axhline(0.5, color="k", ls=":", lw=0.8)
        ax.set_xticks(range(len(seps)), [f"{s:g} {separation_unit}".strip() for s in seps])
        ax.set_xlabel(separation_label)
        ax.set_ylabel("proportion correct")
        ax.set_ylim(0.0, max(1.0, level + 0.25))
        handles, labels = ax.get_legend_handles_labels()
        handles.append(Line2D([], [], color="k", ls=":", lw=0.8))
        labels.append("chance")
        ax.legend(handles, labels, frameon=False, loc="upper left", ncol=2)
        ax.set_title(title)
        caption(fig, f"Bars: mean ± SE across participants. Stars: paired t-tests, Bonferroni over m = {m_family}\n"
                     "(* p ≤ 0.05, ** p ≤ 0.01, *** p ≤ 0.001).")
        mark_simulated(fig, simulated)
    return fig


def plot_reach(reaches: pd.DataFrame, lines: pd.DataFrame, x: str = "target_fraction", y: str = "reach_fraction",
               condition: str = "rendering", simulated: bool = False,
               title: str = "Egocentric blind reaching", test_model: str = "") -> plt.Figure:
    """Reach against target (fractions of arm reach): one panel per condition with each participant's
    mean reach per target (dots) and the condition's fitted line; the other condition's line dashed."""
    conds = sorted(reaches[condition].astype(str).unique())
    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(1, len(conds), figsize=(4.0 * len(conds), 4.2), sharex=True, sharey=True, squeeze=False)
        per = reaches.groupby([condition, "participant", x])[y].mean().reset_index()
        x_lo, x_hi = float(reaches[x].min()) - 0.05, float(reaches[x].max()) + 0.05
        y_lo = min(x_lo, float(per[y].min()) - 0.05)
        y_hi = max(x_hi, float(per[y].max()) + 0.05)
        xs = np.linspace(x_lo, x_hi, 20)
        n_per = int(reaches.groupby([condition, "participant", x]).size().median())
        handles = {}
        for ax, cond in zip(axes[0], conds):
            sub = per[per[condition].astype(str) == cond]
            colour = MODE_COLOURS.get(cond, "C0")
            handles[f"participant mean ({n_per} reaches), {mode_label(cond)}"] = ax.plot(
                sub[x], sub[y], "o", ms=3.5, alpha=0.6, color=colour)[0]
            for other in conds:
                r = lines[lines[condition].astype(str) == other].iloc[0]
                style = dict(color=MODE_COLOURS.get(other, "C1"), lw=1.8) if other == cond else \
                    dict(color=MODE_COLOURS.get(other, "C1"), lw=1.2, ls="--")
                h = ax.plot(xs, r["intercept"] + r["slope"] * xs, **style)[0]
                if other == cond:
                    handles[f"fit, {mode_label(other)}: {r['slope']:.3f} x + {r['intercept']:.3f}"] = h
            handles["other condition's fit (dashed, in its colour)"] = Line2D([], [], color="k", lw=1.2, ls="--")
            handles["veridical (reach = target)"] = ax.plot([x_lo, x_hi], [x_lo, x_hi], "k:", lw=0.8)[0]
            ax.set_xlim(x_lo, x_hi)
            ax.set_ylim(y_lo, y_hi)
            ax.set_title(mode_label(cond))
            ax.set_xlabel("target distance (fraction of arm reach)")
            ax.grid(True, alpha=0.3)
        axes[0, 0].set_ylabel("reach (fraction of arm reach)")
        fig.suptitle(title)
        fig.tight_layout(rect=(0, 0.2, 1, 1))
        fig.legend(list(handles.values()), list(handles.keys()), loc="lower center", ncol=2, frameon=False,
                   bbox_to_anchor=(0.5, 0.04))
        # the caption names the model the condition test actually fitted (a fallback included), never an assumed one
        model = test_model or "see results/summary.md"
        caption(fig, "Distances along the horizontal eye-to-target direction. Lines: linear fits to all reaches of a "
                     f"condition;\ncondition test: {model} (results/summary.md).")
        mark_simulated(fig, simulated)
    return fig


def plot_preferences(prefs: pd.DataFrame, simulated: bool = False) -> plt.Figure:
    """Percent of trials the first mode of each pair was chosen: error bars ± SE across participants;
    stars: one-tailed binomial test against 50 % over all trials."""
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        labels = [f"{mode_label(a)}\nover\n{mode_label(b)}" for a, b in zip(prefs["first"], prefs["second"])]
        xs = np.arange(len(prefs))
        se = prefs["se_subjects"].fillna(prefs["se"]) * 100
        ax.bar(xs, prefs["proportion"] * 100, yerr=se, capsize=4, color="#1f77b4", label="% chosen, mean ± SE across participants")
        for x, p, e, s in zip(xs, prefs["proportion"] * 100, se, prefs["stars"]):
            ax.text(float(x), p + e + 1.5, s, ha="center", fontsize=10)
        ax.axhline(50, color="k", ls=":", lw=0.8, label="no preference (50 %)")
        ax.set_xticks(xs, labels)
        ax.set_ylabel("% of trials the first mode was chosen")
        ax.set_ylim(0, 110)
        ax.legend(loc="upper right", frameon=False)
        ax.set_title("Perceptual realism (pairwise preference)")
        fig.tight_layout(rect=(0, 0.1, 1, 1))
        caption(fig, "Stars: one-tailed binomial test against 50 % over all trials\n(* p ≤ 0.05, ** p ≤ 0.01, *** p ≤ 0.001).",
                y=0.08)
        mark_simulated(fig, simulated)
    return fig
