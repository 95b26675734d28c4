"""``psyop power`` with the image observer (``observer: {kind: image}``): the session path runs it (each session
renders its intervals) and says which observer answered; the direct re-simulation, which renders nothing, refuses
it with one line at the protocol's ``kind: image``. Kept cheap: two trials per session at a tenth of the display's
resolution."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from psyop.errors import UserError
from psyop.power.direct import direct_trials
from psyop.power.replicate import ReplicationTask, run_replication
from tests.session.test_image_observer import image_protocol


def _text() -> str:
    text = image_protocol().replace("levels: [0, 0.25, 0.5, 0.75, 1]", "levels: [0, 1]")
    return re.sub(r"(?m)^(\s*repetitions:)\s*\d+", r"\g<1> 1", text)


def test_the_direct_path_refuses_the_image_observer_at_its_line() -> None:
    text = _text()
    with pytest.raises(UserError) as info:
        direct_trials(ReplicationTask(text, "study.yaml", (), 2, 0, 1))
    line = next(i for i, t in enumerate(text.splitlines(), 1) if t == "  kind: image")
    assert info.value.location == f"study.yaml:{line}:9", info.value.location
    assert "\n" not in str(info.value) and "psyop power" in info.value.message and info.value.exit_code == 2


def test_power_runs_the_image_observer_through_sessions(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    result = run_replication(ReplicationTask(_text(), "study.yaml", (), 2, 0, 1))
    assert result.n_trials == 4 and len(result.outcomes) >= 1  # 2 participants x 2 trials, every one answered

    from psyop.cli import main

    path = tmp_path / "study.yaml"
    path.write_text(_text())
    assert main(["power", str(path), "--participants", "2", "--replications", "1", "--no-checkpoint",
                 "--no-progress", "--jobs", "1"]) == 0
    assert "SIMULATED (observer: image (from the rendered frames))" in capsys.readouterr().out
