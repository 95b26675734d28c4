"""`psyop run --help` describes every source the runner accepts."""

from __future__ import annotations

import re

import pytest

from psyop.cli import main as cli_main


def test_run_help_describes_every_response_tracker_and_pose_source(capsys: pytest.CaptureFixture[str],
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "100000")  # argparse wraps at hyphens otherwise
    with pytest.raises(SystemExit) as exit_info:
        cli_main(["run", "--help"])
    assert exit_info.value.code == 0
    text = re.sub(r"\s+", " ", capsys.readouterr().out)
    responses = text[text.rindex("--responses RESPONSES"):]  # the option's own help (other options mention it)
    for source in ("sim", "keyboard", "serial:DEVICE", "none: nobody"):
        assert source in responses, source
    assert "timeout_s" in responses  # --responses none needs the protocol's timeout
    for source in ("replay:FILE", "pupil:HOST:PORT", "serial:DEVICE"):
        assert source in text[text.rindex("--tracker TRACKER"):], source
    for source in ("replay:SESSION_DIR", "replay-by-condition:SESSION_DIR"):
        assert source in text[text.rindex("--pose POSE"):], source
