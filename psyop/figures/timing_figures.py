"""The timing figure of a session (``psyop timing``): frame intervals against the refresh period,
dropped frames per trial, measured against nominal phase durations and the gaze-to-photon age of every frame
with valid gaze by phase kind, with the protocol's bound (psyop.session.timing.TimingReport)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from psyop.figures.output import save_figure
from psyop.session.timing import TimingReport


def timing_figure(report: TimingReport, out_png: Path) -> list[Path]:
    """Draw ``report`` into ``out_png`` (and a PDF beside it); the paths written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (hist, drops, phases, ages) = plt.subplots(1, 4, figsize=(17, 3.8))
    period_ms = float(report.summary["refresh_period_s"]) * 1e3
    intervals_ms = np.asarray(report.intervals_s, dtype=np.float64) * 1e3
    if intervals_ms.size:
        hist.hist(intervals_ms, bins=min(60, max(10, intervals_ms.size // 5)), color="0.4")
    for k in (1, 2, 3):
        hist.axvline(k * period_ms, color="tab:red", lw=1, ls="-" if k == 1 else ":",
                     label="refresh period" if k == 1 else None)
    hist.set(xlabel="frame interval (ms)", ylabel="frames", title="frame intervals")
    hist.legend(frameon=False)
    drops.bar(report.trials, report.dropped_per_trial, color="tab:orange", width=0.8)
    drops.set(xlabel="trial", ylabel="dropped frames", title=f"dropped frames per trial (total "
              f"{report.summary['dropped_frames']})")
    for i, phase in enumerate(report.phases):
        got = np.asarray(phase.measured_s, dtype=np.float64) * 1e3
        x = np.full(got.size, i) + np.linspace(-0.2, 0.2, got.size) if got.size > 1 else np.full(got.size, float(i))
        phases.scatter(x, got, s=10, color="tab:blue", label="measured" if i == 0 else None)
        phases.hlines(phase.nominal_s * 1e3, i - 0.35, i + 0.35, color="k", lw=2, label="nominal" if i == 0 else None)
    phases.set_xticks(range(len(report.phases)), [p.label for p in report.phases], rotation=30, ha="right")
    phases.set(ylabel="phase duration (ms)", title=f"measured vs nominal (+-1 period = {period_ms:.1f} ms)")
    if report.phases:
        phases.legend(frameon=False)
    _gaze_ages(ages, report)
    fig.suptitle(f"{report.session} ({report.clock} clock{', simulated' if report.simulated else ''})", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, out_png)


def _gaze_ages(ax, report: TimingReport) -> None:  # ax: a matplotlib Axes
    """The gaze-to-photon age histogram, one step outline per phase kind, the bound dashed."""
    by_kind: dict[str, list[float]] = {}
    for kind, age in report.gaze_ages_s:
        by_kind.setdefault(kind, []).append(age * 1e3)
    every = np.concatenate([np.asarray(v) for v in by_kind.values()]) if by_kind else np.zeros(0)
    bins = np.linspace(float(every.min()), float(every.max()) + 1e-6, 40) if every.size else 10
    for kind, ages in sorted(by_kind.items()):
        ax.hist(ages, bins=bins, histtype="step", lw=1.2, label=f"{kind} ({len(ages)})")
    bound = report.gaze_age.get("max_gaze_age_ms")
    if bound is not None:
        ax.axvline(float(bound), color="tab:red", ls="--", lw=1, label="bound (intrinsic)")
    ax.set(xlabel="gaze age at display (ms)", ylabel="frames", title="gaze-to-photon age (valid gaze)")
    if by_kind:
        ax.legend(frameon=False, fontsize=7)
