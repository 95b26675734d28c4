"""The session's backends are closed by one owner (psyop.run.assembly), in reverse order, whatever
raises: a response source whose close raises still lets the tracker, the pose source and the display
close, and the raw gaze no trial recorded is still flushed (issue 28 item 1)."""

from __future__ import annotations

from pathlib import Path

import pytest
from session_helpers import small_protocol

from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.session.frames import HeadlessDisplay
from psyop.session.gaze.simulated import SimulatedTracker
from psyop.session.pose import SimulatedPose
from psyop.session.responses.simulated import SimulatedObserver
from psyop.run.runner import SessionOptions, run_session


def test_display_closed_when_responses_close_raises(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    closed: list[str] = []

    def failing_close(self: object) -> None:
        closed.append("responses")
        raise RuntimeError("response box gone")

    for name, cls in (("display", HeadlessDisplay), ("tracker", SimulatedTracker), ("pose", SimulatedPose)):
        original = cls.close

        def recording_close(self: object, _name: str = name, _original=original) -> None:
            closed.append(_name)
            _original(self)
        monkeypatch.setattr(cls, "close", recording_close)
    monkeypatch.setattr(SimulatedObserver, "close", failing_close)
    protocol = load_protocol(small_protocol(tmp_path, "detection", 1))
    options = SessionOptions(participant="S01", data_root=tmp_path / "data", progress=False,
                             write_description=False, render="cameras")
    with pytest.raises(RuntimeError, match="response box gone"):
        run_session(protocol, compile_schedule, options)
    assert closed[0] == "responses" and closed[-1] == "display"
    assert {"tracker", "pose"} <= set(closed)
    assert closed.index("tracker") < closed.index("pose") < closed.index("display")
