"""Text that cannot be drawn legibly on the session's display is refused when the session starts: ``psyop run``
in a window too small for the protocol's question at the legible minimum (capitals of MIN_CAP_HEIGHT_PX) exits 2
with one line naming the protocol line, the view and the fix, and records no trial."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs xvfb-run (Debian xvfb)")
def test_a_window_too_small_for_the_question_is_refused_at_start_naming_its_line(tmp_path: Path) -> None:
    protocol = REPO / "protocols" / "detection.yaml"
    done = subprocess.run(["xvfb-run", "-a", sys.executable, "-m", "psyop", "run", str(protocol), "--participant", "T1",
                           "--data", str(tmp_path / "data"), "--display", "window", "--responses", "keyboard",
                           "--clock", "real", "--no-progress", "--window-scale", "0.1"],
                          cwd=REPO, capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert done.returncode == 2, done.stderr[-2000:]
    errors = [line for line in done.stderr.splitlines() if "error" in line]
    assert len(errors) == 1 and "Traceback" not in done.stderr
    line = next(i for i, text in enumerate(protocol.read_text().splitlines(), 1) if text.strip().startswith("question:"))
    assert re.search(rf"detection\.yaml:{line}:\d+: on a 144x160 px view, the text takes \d+ lines", errors[0])
    assert "a larger --window-scale" in errors[0]
    assert not list((tmp_path / "data").rglob("trials*.parquet"))  # nothing ran
