"""Issue 31's stress test: real-clock sessions whose frames cannot keep up keep real time.

Every third frame takes 2.3 display periods (:class:`timing_helpers.SlowRenderer`), on the headless display
and on a real window under Xvfb. The session must end with every phase's measured duration within one
refresh period of nominal, the moving target drawn where its path is at each frame's display time, and
dropped-frame counts equal to what the logged display times imply (:func:`timing_helpers.check_session`).
Nothing is asserted of wall-clock durations: only consistency between the logged times, the nominal
durations and the counts.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import psyop.run.runner as runner
from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.run.runner import SessionOptions, run_session

from timing_helpers import SlowRenderer, check_session, timing_protocol

pytestmark = pytest.mark.slow


def test_headless_real_clock_keeps_real_time_when_frames_cannot_keep_up(tmp_path: Path,
                                                                        monkeypatch: pytest.MonkeyPatch,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(runner, "CameraRenderer", SlowRenderer)
    SlowRenderer.calls = []
    outcome = run_session(load_protocol(timing_protocol(tmp_path)), compile_schedule, SessionOptions(
        participant="T1", data_root=tmp_path / "data", clock="real", display="headless", progress=False,
        render="cameras"))
    assert outcome.status == "complete", outcome.message
    dropped = check_session(tmp_path / "data" / "detection" / "sub-T1" / "ses-1", SlowRenderer.calls)
    assert dropped > 0  # the frames really could not keep up (else the test proves nothing)
    # psyop run's closing lines say so (psyop.cli.run._print_integrity_warnings, after print_outcome)
    from psyop.cli.run import _print_integrity_warnings

    capsys.readouterr()
    _print_integrity_warnings(tmp_path / "data", "detection", "T1", 1)
    warning = capsys.readouterr().err
    assert "display periods were skipped" in warning and "psyop timing" in warning, warning


WINDOW_SCRIPT = textwrap.dedent(
    """
    import json, sys
    from pathlib import Path
    sys.path.insert(0, {helpers!r})
    from timing_helpers import SlowRenderer, timing_protocol
    import psyop.run.runner as runner
    from psyop.protocol import load_protocol
    from psyop.schedule import compile_schedule
    from psyop.run.runner import SessionOptions, run_session

    runner.CameraRenderer = SlowRenderer
    outcome = run_session(load_protocol(timing_protocol(Path({tmp!r}))), compile_schedule, SessionOptions(
        participant="W1", data_root=Path({tmp!r}) / "data", clock="real", display="window", progress=False,
        render="cameras", window_scale=0.5))
    Path({calls!r}).write_text(json.dumps(SlowRenderer.calls))
    print(outcome.status)
    """
)


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs xvfb-run (Debian xvfb)")
def test_window_real_clock_keeps_real_time_when_frames_cannot_keep_up(tmp_path: Path) -> None:
    calls = tmp_path / "calls.json"
    script = WINDOW_SCRIPT.format(helpers=str(Path(__file__).parent), tmp=str(tmp_path), calls=str(calls))
    result = subprocess.run(["xvfb-run", "-a", sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.split()[-1] == "complete"
    session = tmp_path / "data" / "detection" / "sub-W1" / "ses-1"
    dropped = check_session(session, [tuple(c) for c in json.loads(calls.read_text())])
    assert dropped > 0
    meta = json.loads((session / "session.json").read_text())
    assert meta["summary"]["display"]["display"] == "window"
    assert meta["summary"]["display"]["frames_missed"] == dropped
