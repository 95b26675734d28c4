"""``psyop timing PATH``: prints a session's measured timing and writes its figure; skips simulated sessions when
asked (what `make figures` runs)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.run.runner import SessionOptions, run_session

from timing_helpers import timing_protocol

ROOT = Path(__file__).resolve().parents[2]


def _psyop(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "psyop", *args], capture_output=True, text=True, cwd=ROOT, timeout=120)


def test_timing_prints_the_summary_and_writes_the_figure(tmp_path: Path) -> None:
    run_session(load_protocol(timing_protocol(tmp_path)), compile_schedule, SessionOptions(
        participant="C1", data_root=tmp_path / "data", clock="virtual", display="headless", progress=False,
        render="cameras", every_frame=True))
    result = _psyop("timing", str(tmp_path / "data"), "--out", str(tmp_path / "figs"))
    assert result.returncode == 0, result.stderr
    assert "virtual clock, simulated:" in result.stdout and "frame interval median 33.33 ms" in result.stdout
    assert "dropped frames: 0" in result.stdout
    assert "interval1 (stimulus): nominal 200.0 ms, measured median 200.0 ms" in result.stdout
    figure = tmp_path / "figs" / "timing_detection_sub-C1_ses-1.png"
    assert figure.is_file() and figure.with_suffix(".pdf").is_file()
    skipped = _psyop("timing", str(tmp_path / "data"), "--out", str(tmp_path / "none"), "--skip-simulated")
    assert skipped.returncode == 0 and "no real sessions" in skipped.stdout
    assert not (tmp_path / "none").exists()


def test_timing_of_nothing_is_one_line_exit_2(tmp_path: Path) -> None:
    result = _psyop("timing", str(tmp_path / "missing"))
    assert result.returncode == 2 and "Traceback" not in result.stderr
    result = _psyop("timing", str(tmp_path))
    assert result.returncode == 2 and "no sessions here" in result.stderr
