"""cProfile of one detection replication at 6 participants (the replication issue 30's 5x goal is
about): the functions with the largest cumulative and own (tottime) shares of the profiled time.

One warm-up replication (2 participants, replication 99: imports and caches are not counted), then
replication 0 at 6 participants (seed 0) under ``cProfile``; the table lists the top functions by
own time and by cumulative time, each as a share of the profiled total. cProfile's overhead
inflates call-heavy functions, so the shares are a map of where to look, not times.
"""

from __future__ import annotations

import cProfile
import pstats
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TOP = 25


def _rows(stats: pstats.Stats, key: int, total_s: float) -> list[str]:
    entries = sorted(stats.stats.items(), key=lambda item: item[1][key], reverse=True)[:TOP]  # type: ignore[attr-defined]
    rows = []
    for (file, line, name), (_, calls, own_s, cum_s, _) in entries:
        where = f"{Path(file).name}:{line} {name}" if line else name
        rows.append(f"| {where} | {calls} | {own_s:.3f} ({100 * own_s / total_s:.1f} %) "
                    f"| {cum_s:.3f} ({100 * cum_s / total_s:.1f} %) |")
    return rows


def run(out_dir: Path, quick: bool) -> str:
    from psyop.power.replicate import ReplicationTask, run_replication

    path = ROOT / "protocols" / "detection.yaml"
    text = path.read_text()
    run_replication(ReplicationTask(text, str(path), (), 2, 99, 0))
    profile = cProfile.Profile()
    profile.enable()
    run_replication(ReplicationTask(text, str(path), (), 2 if quick else 6, 0, 0))
    profile.disable()
    profile.dump_stats(str(out_dir / "power_profile.prof"))
    stats = pstats.Stats(profile)
    total_s = stats.total_tt  # type: ignore[attr-defined]
    head = ["| function | calls | own s (share) | cumulative s (share) |", "|---|---:|---:|---:|"]
    lines = ["## cProfile of one detection replication at 6 participants (bench_power_profile)", "",
             f"Profiled total {total_s:.2f} s (under cProfile); full profile in power_profile.prof.", "",
             f"Top {TOP} by own time:", "", *head, *_rows(stats, 2, total_s), "",
             f"Top {TOP} by cumulative time:", "", *head, *_rows(stats, 3, total_s)]
    return "\n".join(lines)
