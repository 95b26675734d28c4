"""The session-plan benchmark runs (its numbers are for bench/REPORT.md, not asserted here)."""

from __future__ import annotations

from pathlib import Path


def test_session_plan_benchmark_runs(tmp_path: Path) -> None:
    from benchmarks.bench_session_plan import STUDIES, run

    report = run(tmp_path, quick=True)
    assert all(f"| {study} |" in report for study in STUDIES) and "Median ratio plan / old" in report
