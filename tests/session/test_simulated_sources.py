"""A session is real or simulated as a whole: any simulated source marks it, and says which
(`--tracker sim --responses openxr` was recorded `"simulated": false`)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from psyop.cli import main
from psyop.session.runner import SessionOptions
from session_helpers import small_protocol


@pytest.mark.parametrize(("tracker", "responses", "pose", "simulated", "sources"), [
    ("sim", "sim", "sim", True, ["tracker:sim", "responses:sim", "pose:sim"]),
    ("sim", "openxr", "openxr", True, ["tracker:sim"]),  # simulated gaze drove the rendering
    ("openxr", "sim", "openxr", True, ["responses:sim"]),
    ("replay:old/ses-1", "keyboard", "sim", True, ["tracker:replay:old/ses-1", "pose:sim"]),
    ("pupil:127.0.0.1:50020", "keyboard", "sim", False, ["pose:sim"]),  # no head tracker on a desktop
    ("openxr", "openxr", "openxr", False, []),
])
def test_simulated_sources(tracker: str, responses: str, pose: str, simulated: bool, sources: list[str]) -> None:
    options = SessionOptions("P1", tracker=tracker, responses=responses, pose=pose)
    assert options.simulated is simulated and list(options.simulated_sources) == sources


def test_a_replayed_gaze_session_is_recorded_simulated(tmp_path: Path) -> None:
    protocol = small_protocol(tmp_path, "ordinal", 1)
    data = tmp_path / "data"
    base = ["run", str(protocol), "--data", str(data), "--no-progress", "--render", "cameras"]
    assert main([*base, "--participant", "A1"]) == 0
    original = next(data.glob("*/sub-A1/ses-1"))
    assert main([*base, "--participant", "B1", "--tracker", f"replay:{original}"]) == 0
    meta = json.loads(next(data.glob("*/sub-B1/ses-1/session.json")).read_text())
    assert meta["simulated"] is True, meta["simulated_sources"]
    assert meta["simulated_sources"] == [f"tracker:replay:{original}", "responses:sim", "pose:sim"]
