"""The Pupil Remote test server against the official Pupil Core client (pupil-core-network-client):
an independent check that the stand-in answers the command set Pupil Capture does."""

from __future__ import annotations

import time

import pytest
from pupil_labs.pupil_core_network_client import Device
from pupil_server import FakePupilCapture
from session_helpers import wait_until

pytestmark = pytest.mark.timeout(120)


def test_official_client_connects_and_runs_every_command() -> None:
    server = FakePupilCapture(offset_s=500.0)
    try:
        # connect() sends a multipart notify.* announcement, PUB_PORT, SUB_PORT and 10 't' requests
        device = Device("127.0.0.1", server.port, client_clock=time.monotonic)
        assert (device.ipc_pub_port, device.ipc_sub_port) == (server.pub_port, server.sub_port)
        assert device.clock_offset_statistics.mean_offset == pytest.approx(500.0, abs=0.05)
        assert device.request_version() == server.version
        assert device.request_current_pupil_time() == pytest.approx(server.pupil_time(), abs=0.05)
        assert any(n["subject"].startswith("pupil_labs.pupil_core_network_client.connected") for n in server.notifications)

        calibration = device.subscribe("notify.calibration.")
        recording = device.subscribe("notify.recording.")
        gaze = device.subscribe("gaze.3d.")
        wait_until(lambda: gaze.recv_new_message(timeout_ms=100) is not None, what="gaze through the backbone")
        assert device.request_calibration_start() == "OK"

        def subjects(subscription) -> list[str]:  # type: ignore[no-untyped-def]
            found = []
            while (message := subscription.recv_new_message(timeout_ms=50)) is not None:
                found.append(message.payload["subject"])
            return found

        seen: list[str] = []
        wait_until(lambda: seen.extend(subjects(calibration)) or "calibration.successful" in seen,
                   what="calibration.successful")
        assert seen[:3] == ["calibration.should_start", "calibration.started", "calibration.successful"]
        assert device.request_calibration_stop() == "OK"

        assert device.request_recording_start("psyop_test") == "OK"
        seen = []
        wait_until(lambda: seen.extend(subjects(recording)) or "recording.started" in seen, what="recording.started")
        assert server.recording == "psyop_test"
        assert device.request_recording_stop() == "OK"
        wait_until(lambda: server.recording is None, what="recording stopped")

        reply = device.send_annotation("trial", timestamp=device.current_pupil_time(), duration=1.5, trial=3)
        assert reply == "Message forwarded."
        assert server.annotations[-1]["label"] == "trial" and server.annotations[-1]["trial"] == 3
        assert device.send_notification({"subject": "start_plugin", "name": "Annotation_Capture"}) == "Message forwarded."
        assert device._send_recv_command("T 10.0") == "Timesync successful."
        assert server.pupil_time() == pytest.approx(10.0, abs=0.5)
        assert device._send_recv_command("X") == "Unknown command."
        for subscription in (calibration, recording, gaze):
            subscription.disconnect()
        device.disconnect()
    finally:
        server.stop()


def test_failed_calibration_is_announced() -> None:
    server = FakePupilCapture()
    server.calibration_fails = True
    try:
        device = Device("127.0.0.1", server.port)
        calibration = device.subscribe("notify.calibration.failed")
        device.request_calibration_start()
        message = None

        def failed() -> bool:
            nonlocal message
            message = calibration.recv_new_message(timeout_ms=100)
            return message is not None

        wait_until(failed, what="calibration.failed")
        assert message is not None and "reason" in message.payload
        calibration.disconnect()
        device.disconnect()
    finally:
        server.stop()


def test_session_calibrates_records_and_annotates_every_trial(tmp_path) -> None:  # type: ignore[no-untyped-def]
    import json

    import pandas as pd
    from session_helpers import fast_protocol

    from psyop.protocol import load_protocol
    from psyop.schedule import compile_schedule
    from psyop.session.log.layout import session_paths
    from psyop.run.runner import SessionOptions, run_session

    server = FakePupilCapture()
    try:
        protocol = load_protocol(fast_protocol(tmp_path, "realism", repetitions=1, phase_s=0.05))
        data = tmp_path / "data"
        options = SessionOptions(participant="P1", seed=1, tracker=f"pupil:127.0.0.1:{server.port},calibrate,record,annotate",
                                 clock="real", data_root=data, progress=False, render="cameras")
        outcome = run_session(protocol, compile_schedule, options)
    finally:
        server.stop()
    assert outcome.status == "complete", outcome.message
    subjects = [n["subject"] for n in server.notifications]
    for subject in ("start_plugin", "calibration.should_start", "calibration.successful", "recording.should_start",
                    "recording.stopped"):
        assert subject in subjects, subject
    assert subjects.index("calibration.successful") < subjects.index("recording.should_start")
    started = next(n for n in server.notifications if n["subject"] == "recording.started")
    assert started["session_name"] == f"{protocol.study.name}_sub-P1_ses-1"
    assert server.recording is None  # stopped at the end
    paths = session_paths(data, protocol.study.name, "P1", 1)
    trials = pd.read_parquet(paths.trials_parquet)
    meta = json.loads(paths.metadata.read_text())
    assert meta["tracker_at_start"]["calibration"]["result"] == "successful"
    annotations = [a for a in server.annotations if a.get("source") == "psyop"]
    assert [a["trial"] for a in annotations] == trials["trial"].tolist()  # one per recorded trial, in order
    assert [a["condition"] for a in annotations] == trials["condition"].tolist()
    sync = meta["runs"][0]["clock_sync"]
    for a, row in zip(annotations, trials.itertuples(), strict=True):
        assert a["label"] == "trial"
        assert a["duration"] == pytest.approx(row.trial_end_s - row.trial_start_s, abs=1e-9)
        # Pupil time of the trial's start (the fit at the time; later refits move it by well under 10 ms)
        assert a["timestamp"] == pytest.approx(sync["offset_s"] + (1 + sync["drift"]) * row.trial_start_s, abs=0.01)
    tracker = meta["summary"]["tracker"]
    assert tracker["annotations_sent"] == tracker["annotations_confirmed"] == len(trials)


def test_a_failed_calibration_stops_the_session_before_its_first_trial(tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    from session_helpers import fast_protocol

    from psyop.cli import main as cli_main

    server = FakePupilCapture()
    server.calibration_fails = True
    try:
        protocol = fast_protocol(tmp_path, "realism", repetitions=1)
        code = cli_main(["run", str(protocol), "--participant", "P1", "--data", str(tmp_path / "data"), "--no-progress",
                         "--clock", "real", "--render", "cameras", "--tracker", f"pupil:127.0.0.1:{server.port},calibrate"])
    finally:
        server.stop()
    assert code == 3
    err = capsys.readouterr().err
    assert "calibration did not succeed (failed: Not enough ref points" in err
    assert not list((tmp_path / "data").rglob("trials-*.psylog"))  # nothing started
