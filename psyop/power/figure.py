"""Power against sample size, one line per reported test, with the binomial CIs."""

from __future__ import annotations

import pandas as pd
from matplotlib.figure import Figure


def plot_power(table: pd.DataFrame, title: str) -> Figure:
    fig = Figure(figsize=(6.4, 4.2))
    ax = fig.add_subplot()
    for test, rows in table.groupby("test", sort=False):
        rows = rows.sort_values("participants")
        ax.errorbar(rows["participants"], rows["power"],
                    yerr=[rows["power"] - rows["ci_low"], rows["ci_high"] - rows["power"]],
                    marker="o", capsize=3, label=str(test))
    alpha = float(table["alpha"].iloc[0]) if len(table) else 0.05
    ax.axhline(0.8, color="0.6", lw=0.8, ls="--")
    ax.set_xticks(sorted(int(n) for n in table["participants"].unique()))
    ax.set_xlabel("participants")
    ax.set_ylabel(f"power (share of replications with p < {alpha:g})")
    ax.set_ylim(0, 1.02)
    n = int(table["n_replications"].max()) if len(table) else 0
    ax.set_title(f"{title}\nSIMULATED: {n} replications per point, 95 % Clopper-Pearson CIs", fontsize=9)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    return fig
