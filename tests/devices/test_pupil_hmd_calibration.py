"""In-headset calibration of Pupil Core (``pupil:...,calibrate-hmd``) against a server speaking Capture's protocol.

The server (pupil_server.FakePupilCapture) answers the HMD 3D choreography's notifications as Capture does and fits
a real mapping from the reference data it receives (pupil_hmd_model): reference points matched in time to the
participant's pupil data, each eye camera's rotation fitted from the directions to them. The participant looks at
each target psyop draws (the tests move the server's eyes as each target is shown: the drawing path's
``hold_target`` tells them), so a calibration succeeds only when psyop sends the positions in the frame and unit,
and the times on the clock, that Capture's gaze comes back in; the gaze mapped afterwards must then decode at the
targets. The mutation tests change one of those and see it fail.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from pupil_server import FakePupilCapture
from session_helpers import fast_protocol, wait_until

import psyop.devices.gaze.pupil_hmd_calibration as hmd_module
import psyop.run.headset as run_headset
import psyop.run.runner as runner_module
import psyop.session.headset_calibration as calibration_module
import psyop.session.validation as validation_module
from psyop.devices.gaze.pupil import PupilClient
from psyop.devices.gaze.pupil_hmd_calibration import PupilHmdCalibration, plugin_for_version
from psyop.errors import UserError
from psyop.optics.angles import fick_direction
from psyop.protocol import load_protocol
from psyop.run.runner import SessionOptions, run_session
from psyop.schedule import compile_schedule
from psyop.session.clock import RealClock
from psyop.session.gaze.sync import ClockSync
from psyop.session.headset_calibration import CalibrationLayout, CalibrationResult, eye_centres_m
from psyop.session.log.store import SessionStore

#: a short layout for tests: the stated targets, 0.1 s to look, 12 frames of reference data each
SHORT = CalibrationLayout(settle_s=0.1, frames_per_target=12, result_timeout_s=10.0)


def _world_mm(point_m: tuple[float, float, float]) -> list[float]:
    """Pupil's world-camera convention (x right, y down, z forward, mm), written out here on its own."""
    return [1000.0 * point_m[0], -1000.0 * point_m[1], -1000.0 * point_m[2]]


@pytest.fixture
def started() -> Iterator[tuple[FakePupilCapture, PupilClient, RealClock]]:
    server = FakePupilCapture(offset_s=1000.0, version="3.5.1")
    clock = RealClock()
    client = PupilClient("127.0.0.1", server.port, clock=clock.now_s)
    try:
        client.start()
        yield server, client, clock
    finally:
        client.close()
        server.stop()


def _calibrate(server: FakePupilCapture, client: PupilClient, clock: RealClock) -> CalibrationResult:
    """The adapter driven as the calibrator drives it: the eyes on each target, 10 frame times while they look."""
    calibration = PupilHmdCalibration(client)
    calibration.begin(eye_centres_m(server.eyes.separation_m))
    for target in SHORT.targets:
        position = target.position_m()
        server.eyes.look_at_head_m = position
        start = clock.now_s()
        wait_until(lambda: clock.now_s() > start + 0.15, what="the eyes on the target")
        calibration.add_reference(position, np.linspace(start + 0.04, start + 0.13, 10).tolist())
    return calibration.finish(10.0)


def _decoded_at(client: PupilClient, server: FakePupilCapture, point_m: tuple[float, float, float]) -> np.ndarray:
    """Where the client's gaze decodes once the eyes look at ``point_m`` (a sample taken after the move)."""
    server.eyes.look_at_head_m = point_m
    moved = client._clock()
    sample = wait_until(lambda: (s := client.latest(client._clock())) is not None and s.timestamp_s > moved + 0.02 and s,
                        what="a gaze sample after the eyes moved")
    return np.asarray(sample.fixation_m)


def test_plugin_name_follows_captures_version() -> None:
    assert plugin_for_version("3.5.1") == "HMD3DChoreographyPlugin"
    assert plugin_for_version("2.0.182") == "HMD3DChoreographyPlugin"
    assert plugin_for_version("1.23.10") == "HMD_Calibration_3D"


@pytest.mark.parametrize("version", ["3.5.1", "1.23.10"])
def test_calibration_sends_captures_messages_and_mapped_gaze_decodes_at_the_target(version: str) -> None:
    server = FakePupilCapture(offset_s=1000.0, version=version)
    clock = RealClock()
    client = PupilClient("127.0.0.1", server.port, clock=clock.now_s)
    try:
        client.start()
        result = _calibrate(server, client, clock)
        assert result.status == "successful", (result, server.hmd_failure)
        assert server.hmd_plugin == plugin_for_version(version)
        start = next(n for n in server.notifications if n["subject"] == "calibration.should_start")
        assert start["translation_eye0"] == pytest.approx([32.0, 0.0, 0.0])  # eye 0 is the right eye, mm
        assert start["translation_eye1"] == pytest.approx([-32.0, 0.0, 0.0])
        refs = server.hmd_refs
        assert len(refs) == 10 * len(SHORT.targets) and set(refs[0]) == {"mm_pos", "timestamp"}
        assert refs[0]["mm_pos"] == pytest.approx(_world_mm(SHORT.targets[0].position_m()))
        assert abs(refs[-1]["timestamp"] - server.pupil_time()) < 5.0  # Pupil time, not the session clock
        assert result.details["plugin"] == plugin_for_version(version) and result.accuracy_deg is None
        params = result.details["capture_result_params"]
        assert params["binocular_model"]["eye_camera_to_world_matrix0"] if version >= "2" else params is None
        assert max(server.hmd_fit.residual_deg) < 0.05
        # gaze Capture maps now is in the frame of the reference points: it decodes where the eyes look
        for point in [(0.1, 0.05, -0.8), (-0.2, -0.1, -1.5)]:
            assert _decoded_at(client, server, point) == pytest.approx(point, abs=0.005)
    finally:
        client.close()
        server.stop()


def _metres(point_m: tuple[float, float, float]) -> tuple[float, float, float]:
    return (point_m[0], -point_m[1], -point_m[2])  # the right axes, the wrong unit


def _mirrored(point_m: tuple[float, float, float]) -> tuple[float, float, float]:
    return (1000.0 * point_m[0], 1000.0 * point_m[1], -1000.0 * point_m[2])  # y not flipped: a mirror image


def _head_frame(point_m: tuple[float, float, float]) -> tuple[float, float, float]:
    return (1000.0 * point_m[0], 1000.0 * point_m[1], 1000.0 * point_m[2])  # psyop's own axes, unconverted


@pytest.mark.parametrize(("convert", "fits"), [(_metres, True), (_mirrored, False), (_head_frame, True)],
                         ids=["metres", "mirrored", "head-frame"])
def test_a_wrong_frame_or_unit_fails_the_calibration_or_its_gaze(
        started: tuple[FakePupilCapture, PupilClient, RealClock], convert: Callable, fits: bool,
        monkeypatch: pytest.MonkeyPatch) -> None:
    server, client, clock = started
    monkeypatch.setattr(hmd_module, "head_m_to_world_mm", convert)
    result = _calibrate(server, client, clock)
    assert result.succeeded == fits, (result, server.hmd_failure)
    if fits:  # a frame only rotated (or scaled) still fits, as in Capture: the gaze it maps comes back wrong
        point = (0.1, 0.05, -0.8)
        assert np.linalg.norm(_decoded_at(client, server, point) - np.asarray(point)) > 0.1
    else:
        assert result.status == "failed" and result.reason == "Capture's reason: CalibrationError"
        assert "fit did not converge" in str(server.hmd_failure)


def test_reference_times_on_the_session_clock_fail_to_match(
        started: tuple[FakePupilCapture, PupilClient, RealClock], monkeypatch: pytest.MonkeyPatch) -> None:
    server, client, clock = started
    monkeypatch.setattr(client, "clock_sync", lambda: ClockSync(0.0, 0.0, 0.0, 0.0, 3))
    result = _calibrate(server, client, clock)
    assert result.status == "failed" and "matched pupil data in time" in str(server.hmd_failure)
    assert "CalibrationError" in result.reason and "eye windows" in result.fix


def test_a_calibration_capture_does_not_start_is_not_started_and_says_so(
        started: tuple[FakePupilCapture, PupilClient, RealClock]) -> None:
    server, client, clock = started
    running = PupilHmdCalibration(client)
    running.begin(eye_centres_m(0.064))  # Capture ignores should_start while a calibration runs (a warning, no answer)
    second = PupilHmdCalibration(client, reply_timeout_s=1.0)
    try:
        with pytest.raises(hmd_module.CalibrationUnavailable, match="did not answer calibration.should_start"):
            second.begin(eye_centres_m(0.064))
        assert second.finish(1.0).status == "not_started"
    finally:
        running.close()


# -- whole sessions -----------------------------------------------------------------------------------------------

VALIDATION = ("gaze_validation:\n  when: [start]\n  settle_s: 0.1\n  dwell_s: 0.2\n  distance_m: 1.0\n"
              "  points_deg: [[0, 0], [8, 0], [0, -8]]\n  require: {max_mean_error_deg: 0.5, max_attempts: 1}\n")


def _watching(server: FakePupilCapture, monkeypatch: pytest.MonkeyPatch) -> None:
    """The participant looks at every target the drawing path shows (calibration and validation alike), 50 ms
    after it appears."""
    real = validation_module.hold_target

    def look_then_hold(loop, phase, start_s):
        point = tuple(float(v) for v in phase.target_distance_m * fick_direction(*phase.target_deg))
        server.eyes.look_from(server.pupil_time() + 0.05, point)
        return real(loop, phase, start_s)

    monkeypatch.setattr(validation_module, "hold_target", look_then_hold)
    monkeypatch.setattr(calibration_module, "hold_target", look_then_hold)


def _session(tmp_path: Path, server: FakePupilCapture) -> tuple[SessionOptions, object]:
    path = fast_protocol(tmp_path, "detection", repetitions=1, phase_s=0.05)
    path.write_text(path.read_text() + "\n" + VALIDATION)
    options = SessionOptions(participant="P1", seed=3, tracker=f"pupil:127.0.0.1:{server.port},calibrate-hmd",
                             clock="real", data_root=tmp_path / "data", progress=False, render="cameras")
    return options, load_protocol(path)


def _press_c_after(trial: int, monkeypatch: pytest.MonkeyPatch, then: Callable[[], None] = lambda: None) -> None:
    """The experimenter presses c (recalibrate now) once ``trial`` is durable; ``then`` runs right after."""
    controls = []  # the run's control keys (psyop.session.controls)
    real_controls, real_append = runner_module._controls, SessionStore.append_trial
    monkeypatch.setattr(runner_module, "_controls", lambda *a: controls.append(real_controls(*a)) or controls[-1])

    def append_then_press_c(self: SessionStore, row, frames, gaze=None) -> None:
        real_append(self, row, frames, gaze)
        if int(row["trial"]) == trial:
            controls[-1].press("c", "the test")
            then()

    monkeypatch.setattr(SessionStore, "append_trial", append_then_press_c)


def test_session_calibrates_in_the_headset_records_it_and_validates(tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    server = FakePupilCapture(offset_s=1000.0)
    monkeypatch.setattr(run_headset, "CalibrationLayout", lambda: SHORT)
    _watching(server, monkeypatch)
    _press_c_after(2, monkeypatch)
    try:
        options, protocol = _session(tmp_path, server)
        outcome = run_session(protocol, compile_schedule, options)
    finally:
        server.stop()
    assert outcome.status == "complete", outcome.message
    session = tmp_path / "data" / "detection" / "sub-P1" / "ses-1"
    record = json.loads((session / "session.json").read_text())["runs"][0]["headset_calibrations"]
    assert [(r["status"], r["when"], r["before_trial"]) for r in record] == [("successful", "start", 0),
                                                                             ("successful", "recalibrate", 3)]
    references = record[0]["references"]
    assert [r["target"] for r in references] == list(range(9)) and all(r["n_frames"] >= 10 for r in references)
    assert record[-1]["n_reference_frames"] == len(server.hmd_refs)  # the server keeps its last calibration's
    assert record[0]["accuracy_deg"] is None and "validation" in record[0]["accuracy_source"]
    assert record[0]["details"]["gazer"] == "GazerHMD3D"
    validation = pd.read_parquet(session / "validation.parquet")
    overall = validation[validation["point"] == -1]
    assert overall["when"].tolist() == ["start", "recalibrate"]
    assert overall["passed"].all() and (overall["mean_error_deg"] < 0.2).all()  # the mapped gaze lands on the targets
    gaze = pd.read_parquet(session / "gaze.parquet")
    assert (gaze["trial"] == -1).sum() > 0  # the calibration's and validation's raw samples are kept


def test_failed_calibration_stops_with_one_line_and_exit_2(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    server = FakePupilCapture(offset_s=1000.0)  # the participant never looks at the targets: no mapping fits
    monkeypatch.setattr(run_headset, "CalibrationLayout", lambda: SHORT)
    try:
        options, protocol = _session(tmp_path, server)
        with pytest.raises(UserError) as raised:
            run_session(protocol, compile_schedule, options)
    finally:
        server.stop()
    message = str(raised.value)
    assert raised.value.exit_code == 2 and "\n" not in message
    assert "Capture's reason: CalibrationError" in message and "rerun the same command" in message
    session = tmp_path / "data" / "detection" / "sub-P1" / "ses-1"
    meta = json.loads((session / "session.json").read_text())
    assert meta["status"] == "incomplete" and meta["summary"]["outcome"] == "calibration_failed"
    assert [r["status"] for r in meta["runs"][0]["headset_calibrations"]] == ["failed"]
    assert not (session / "trials.parquet").exists() or pd.read_parquet(session / "trials.parquet").empty


def test_a_recalibration_that_fails_stops_after_the_recorded_trials_with_exit_2(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    server = FakePupilCapture(offset_s=1000.0)
    monkeypatch.setattr(run_headset, "CalibrationLayout", lambda: SHORT)
    _watching(server, monkeypatch)
    _press_c_after(1, monkeypatch, then=lambda: setattr(server, "hmd_max_residual_deg", -1.0))  # no fit will do
    try:
        options, protocol = _session(tmp_path, server)
        with pytest.raises(UserError) as raised:
            run_session(protocol, compile_schedule, options)
    finally:
        server.stop()
    assert raised.value.exit_code == 2 and "\n" not in str(raised.value)
    assert str(raised.value).startswith("--tracker: in-headset calibration failed") and "2/15 recorded" in str(raised.value)
    session = tmp_path / "data" / "detection" / "sub-P1" / "ses-1"
    meta = json.loads((session / "session.json").read_text())
    assert meta["status"] == "incomplete"
    assert [(r["status"], r["when"]) for r in meta["runs"][0]["headset_calibrations"]] == [
        ("successful", "start"), ("failed", "recalibrate")]
    assert pd.read_parquet(session / "trials.parquet")["trial"].tolist() == [0, 1]  # nothing recorded is lost
