"""Progress when nobody watches: a few plain lines, not a redrawn bar (issue 13: a 225-trial
run piped to a file wrote about 22 kB of progress-bar redraws)."""

from __future__ import annotations

import io
import os
import subprocess
import sys
from pathlib import Path

from session_helpers import PROTOCOLS

from psyop.session.progress import NoProgress, PlainLines, session_progress

REPO = Path(__file__).resolve().parents[2]


def test_a_piped_225_trial_run_writes_a_few_plain_progress_lines(tmp_path: Path) -> None:
    result = subprocess.run([sys.executable, "-m", "psyop", "run", str(PROTOCOLS / "detection.yaml"), "--participant",
                             "P1", "--seed", "7", "--data", str(tmp_path / "data"), "--render", "cameras"],
                            capture_output=True, env=dict(os.environ, PYTHONPATH=str(REPO)), timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    err = result.stderr.decode()
    assert "\r" not in err and "\x1b" not in err
    progress = [line for line in err.splitlines() if line.startswith("detection sub-P1:")]
    assert progress[0].startswith("detection sub-P1: 0/225 trials") and progress[-1] == "detection sub-P1: 225/225 trials"
    assert 3 <= len(progress) <= 12
    assert len(result.stderr) < 2000


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_terminal_gets_the_live_bar_and_off_is_silent() -> None:
    bar = session_progress(10, 0, "x", enabled=True, stream=_Tty())
    assert type(bar).__name__ == "tqdm"
    bar.close()
    assert isinstance(session_progress(10, 0, "x", enabled=False), NoProgress)


def test_plain_lines_resume_from_the_recorded_count() -> None:
    out = io.StringIO()
    bar = PlainLines(20, 15, "s", out)
    for _ in range(5):
        bar.set_postfix(trial=1)
        bar.update(1)
    bar.close()
    assert out.getvalue().splitlines() == ["s: 15/20 trials", "s: 16/20 trials", "s: 18/20 trials", "s: 20/20 trials"]
