"""Power against sample size, one line per reported test, with the binomial CIs (and, with
``--target-power``, each test's n and its interval marked)."""

from __future__ import annotations

import pandas as pd
from matplotlib.axes import Axes
from matplotlib.colors import to_hex
from matplotlib.figure import Figure


def _mark_targets(ax: Axes, target: pd.DataFrame, colours: dict[str, str]) -> None:
    """A dotted line at each test's n and a band over its interval [n_ci_high, n_ci_low]; a test
    whose target is not reached gets a note in the legend instead (psyop.power.target)."""
    for _, row in target.iterrows():
        colour = colours.get(str(row["test"]), "0.3")
        if pd.isna(row["n"]):
            ax.plot([], [], ls=":", color=colour, label=f"{row['test']}: target not reached "
                    f"by N = {int(row['max_participants'])}")
            continue
        ax.axvline(int(row["n"]), color=colour, ls=":", lw=1.2)
        ax.plot([int(row["n"])], [float(row["power"])], marker="*", ms=13, color=colour, mec="k", mew=0.6, zorder=5)
        low = int(row["n_ci_high"]) if not pd.isna(row["n_ci_high"]) else int(row["n"])
        high = int(row["n_ci_low"]) if not pd.isna(row["n_ci_low"]) else int(row["max_participants"])
        ax.axvspan(low, high, color=colour, alpha=0.08, lw=0)
        upper = str(high) if not pd.isna(row["n_ci_low"]) else f"> {high}"
        at_min = int(row["min_participants"])  # reached at the smallest n tried: fewer may do
        n_text, low_text = (f"<= {at_min}" if int(row["n"]) == at_min else f"= {int(row['n'])}",
                            f"<= {low}" if low == at_min else str(low))
        ax.plot([], [], ls=":", marker="*", color=colour, label=f"{row['test']}: N {n_text} [{low_text}, {upper}]")


def plot_power(table: pd.DataFrame, title: str, target: pd.DataFrame | None = None) -> Figure:
    fig = Figure(figsize=(6.4, 4.2))
    ax = fig.add_subplot()
    colours: dict[str, str] = {}
    for test, rows in table.groupby("test", sort=False):
        rows = rows.sort_values("participants")
        bars = ax.errorbar(rows["participants"], rows["power"],
                           yerr=[rows["power"] - rows["ci_low"], rows["ci_high"] - rows["power"]],
                           marker="o", capsize=3, label=str(test))
        colours[str(test)] = to_hex(bars.lines[0].get_color())
    alpha = float(table["alpha"].iloc[0]) if len(table) else 0.05
    level = float(target["target_power"].iloc[0]) if target is not None and len(target) else 0.8
    ax.axhline(level, color="0.6", lw=0.8, ls="--")
    if target is not None:
        _mark_targets(ax, target, colours)
    ns = sorted(int(n) for n in table["participants"].unique())
    ax.set_xticks(ns if len(ns) <= 12 else ns[:: max(1, len(ns) // 12)])
    ax.set_xlabel("participants")
    ax.set_ylabel(f"power (share of replications with p < {alpha:g})")
    ax.set_ylim(0, 1.02)
    n = int(table["n_replications"].max()) if len(table) else 0
    marked = f"\ntarget power {level:g}: each test's N (star) and its interval (band) marked" if target is not None else ""
    ax.set_title(f"{title}\nSIMULATED: {n} replications per point, 95 % Clopper-Pearson CIs{marked}", fontsize=9)
    ax.legend(fontsize=6 if target is not None else 7, loc="lower right")
    fig.tight_layout()
    return fig
