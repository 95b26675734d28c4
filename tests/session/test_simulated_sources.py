"""A session is real or simulated as a whole: any simulated source marks it, and says which
(`--tracker sim --responses openxr` was recorded `"simulated": false`)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from psyop.cli import main
from psyop.run.runner import SessionOptions
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


@pytest.mark.parametrize(("display", "pose", "reach", "simulated"), [
    ("openxr", "sim", False, True),  # a simulated head pose placed the head the headset's images were rendered for
    ("openxr:xlib", "replay:old/ses-1", False, True),
    ("openxr", "openxr:right", True, False),
    ("window", "sim", False, False),  # a desktop has no head tracker to take the head pose from
    ("window", "sim", True, True),  # but a reach measured on the simulated hand is not a person's
    ("headless", "replay-by-condition:old/ses-1", True, True),
])
def test_a_simulated_pose_decides_where_it_stood_in_for_a_tracker_or_measured_the_answer(
        display: str, pose: str, reach: bool, simulated: bool) -> None:
    tracker = responses = "openxr" if display.startswith("openxr") else "keyboard"
    options = SessionOptions("P1", tracker="pupil:127.0.0.1:50020" if tracker == "keyboard" else tracker,
                             responses=responses, pose=pose, display=display)
    assert options.simulated_for(reach) is simulated, options.simulated_sources
    assert options.simulated_for(reach) is (options.simulated or reach and pose != "openxr:right")


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


def test_session_json_marks_a_reach_study_answered_on_a_simulated_hand() -> None:
    from psyop.protocol import load_protocol
    from psyop.session.plan import compile_plan
    from psyop.run.runner import _simulated

    root = Path(__file__).resolve().parents[2] / "protocols"
    options = SessionOptions("P1", tracker="pupil:127.0.0.1:50020", responses="keyboard", pose="sim", display="window")
    assert _simulated(options, compile_plan(load_protocol(root / "egocentric.yaml"))) is True  # reach: the hand's
    assert _simulated(options, compile_plan(load_protocol(root / "ordinal.yaml"))) is False


def test_session_json_names_the_observer_that_answered_and_none_where_nobody_did(tmp_path: Path) -> None:
    from psyop.protocol import load_protocol

    protocol = small_protocol(tmp_path, "ordinal", 1)
    text = protocol.read_text()
    protocol.write_text(text.replace("      expected_s: 1.5", "      timeout_s: 1.5\n      expected_s: 1.5", 1))
    data = tmp_path / "data"
    base = ["run", str(protocol), "--data", str(data), "--no-progress", "--render", "cameras"]
    assert main([*base, "--participant", "A1"]) == 0
    assert main([*base, "--participant", "N1", "--responses", "none"]) == 0  # every response phase times out
    answered = json.loads(next(data.glob("*/sub-A1/ses-1/session.json")).read_text())
    nobody = json.loads(next(data.glob("*/sub-N1/ses-1/session.json")).read_text())
    observer = load_protocol(protocol).observer
    assert observer is not None and answered["observer"] == observer.kind
    assert nobody["observer"] is None
