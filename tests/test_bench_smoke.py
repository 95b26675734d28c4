"""Smoke runs of the benchmarks whose --quick size fits the suite (bench_power's does not: its
agreement check is tests/power/test_direct_pairing.py)."""

from pathlib import Path

import pytest


def test_bench_adaptive_quick_writes_every_table(tmp_path: Path) -> None:
    from benchmarks import bench_adaptive

    report = bench_adaptive.run(tmp_path, quick=True)
    assert "20 simulated 2AFC observers" in report
    for table in ("| method | observers | median trials", "| method | all: trials", "trials for constant stimuli's SD",
                  "psyop.adaptive.QuestPlus (history -> next level), wall"):
        assert table in report


def test_bench_openxr_frame_quick_reports_the_ratio_or_why_not(tmp_path: Path) -> None:
    from benchmarks import bench_openxr_frame

    report = bench_openxr_frame.run(tmp_path, quick=True)
    assert "## OpenXR frame path over headless" in report
    assert "| ratio openxr / headless |" in report or "Skipped: " in report, report


@pytest.mark.bench  # 14 s; the export's validity: tests/export/test_bids_export.py (the BIDS validator on five studies)
def test_bench_export_quick_validates_the_export(tmp_path: Path) -> None:
    from benchmarks import bench_export

    report = bench_export.run(tmp_path, quick=True)
    assert "5 simulated sessions" in report and "sessions with at least one: 5 of 5" in report
    assert "exit 0, 0 errors" in report or "not installed" in report
    assert "| ratio verify / read |" in report


def test_bench_lsl_quick_measures_both_paths_and_the_raw_stream(tmp_path: Path) -> None:
    from benchmarks import bench_lsl

    report = bench_lsl.run(tmp_path, quick=True)
    for row in ("| Pupil (ZMQ + msgpack, PupilClient) |", "| LSL (Pupil relay outlet, LslGazeSource) |",
                "LSL / Pupil median age: **", "| raw stream total |", "Raw stream total / Pupil per-message work: **"):
        assert row in report
    assert "nan" not in report


def test_bench_adaptive_calibration_quick_writes_its_coverage_table(tmp_path: Path) -> None:
    from benchmarks import bench_adaptive_calibration

    report = bench_adaptive_calibration.run(tmp_path, quick=True)
    assert "| procedure and estimate | trials | observers | coverage | bias (D) | SD / error |" in report
    for name in ("QUEST+ (posterior)", "reversal mean +- SE (before)", "posterior (now logged)"):
        assert name in report
    assert "| procedure | mean trials with the stop | never reached the SD | RMS error (D) |" in report


def test_bench_statistics_lapse_coverage_quick_writes_its_table(tmp_path: Path) -> None:
    from benchmarks import bench_statistics_lapse_coverage

    report = bench_statistics_lapse_coverage.run(tmp_path, quick=True)
    assert "| trials per level | coverage, all | lapse < 0.01 | lapse >= 0.03 | sd < 0.2 D | sd >= 0.3 D |" in report
    assert "| 15 |" in report and "| 1000 |" in report
    assert "Lowest coverage over the rows:" in report and "grid peaks joined" in report


@pytest.mark.bench  # 14 s; the recovery it reports: tests/test_nc_calibration.py
def test_bench_nc_calibration_quick_writes_its_coverage_table(tmp_path: Path) -> None:
    from benchmarks import bench_nc_calibration

    report = bench_nc_calibration.run(tmp_path, quick=True)
    assert "| participants | ok fits | 95 % interval covers the own NC |" in report
    assert "| 3 | " in report and "Quick run" in report and (tmp_path / "nc_calibration.md").is_file()


@pytest.mark.bench  # 80 s of make figures-build before and after: make bench runs it (and the benchmark in full)
def test_bench_figures_power_speed_quick_compares_before_and_after(tmp_path: Path) -> None:
    """Before (the commit before issue 21's figure and power work) and after, side by side; the run
    fails when any output differs byte for byte."""
    from benchmarks import bench_figures_power_speed

    report = bench_figures_power_speed.run(tmp_path, quick=True)
    if "Skipped: " in report:  # a clone without the before commit (shallow): said, not measured
        return
    assert "| make figures-build, simulated data at 3 participants per study (quick), JOBS=2 |" in report
    assert "| psyop power protocols/detection.yaml --participants 2 --replications 1 --jobs 1 |" in report
    assert "| 4 | 12 |" in report and "nan" not in report


@pytest.mark.bench  # 24 s; the equality it reports: tests/session/test_frame_cpu_equality.py
def test_bench_frame_cpu_quick_reports_every_protocol_before_and_after(tmp_path: Path) -> None:
    from benchmarks import bench_frame_cpu

    report = bench_frame_cpu.run(tmp_path, quick=True)
    assert "| scene | eyes | primitives | mode | before ms | of budget | after ms | of budget | after / before |" in report
    for name in bench_frame_cpu.PROTOCOLS:
        assert f"| {name} (as shipped) |" in report
    assert "| detection rendered stereo | 2 |" in report and "| detection stereo + 60 discs | 2 | 64 |" in report
    assert "Cost per primitive per stereo frame" in report and "samples identical: True" in report
    assert "nan" not in report


@pytest.mark.bench  # 20 s, twice with cross_cpu; both paths' equality: tests/power/test_memory_log.py, test_direct_pairing.py
@pytest.mark.cross_cpu
def test_bench_power_stages_quick_reports_both_paths_for_every_study(tmp_path: Path) -> None:
    from benchmarks import bench_power_stages

    report = bench_power_stages.run(tmp_path, quick=True)  # fails itself when the two paths' outcomes differ
    for name in bench_power_stages.PAPER_N:
        assert f"| {name} | 2 | full |" in report and f"| {name} | 2 | replication |" in report


def test_bench_mesh_frame_quick_reports_every_triangle_count(tmp_path: Path) -> None:
    from benchmarks import bench_mesh_frame

    report = bench_mesh_frame.run(tmp_path, quick=True)
    assert "| triangles | mesh frame ms (median) | analytic frame ms | ratio mesh / analytic |" in report
    for n in bench_mesh_frame.TRIANGLES:
        assert f"\n| {n} | " in report
    assert "| box room (kind: room) |" in report and "| dining room (assets/dining_room.glb) |" in report
