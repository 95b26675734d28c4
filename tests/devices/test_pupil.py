"""The Pupil Core client against a ZMQ server speaking the documented wire protocol."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from pupil_server import FakePupilCapture
from session_helpers import fast_protocol, wait_until

from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.session.clock import RealClock
from psyop.devices.gaze.pupil import PupilClient, fit_clock_sync, world_mm_to_head_m
from psyop.session.gaze.sample import TrackerLost
from psyop.session.log.store import SessionStore
from psyop.run.runner import SessionOptions, run_session


def test_fit_clock_sync_recovers_offset_and_drift() -> None:
    rng = np.random.default_rng(0)
    local = np.linspace(0.0, 10.0, 50)
    remote = 123.456 + (1 + 2e-5) * local + rng.normal(0, 1e-5, local.size)
    sync = fit_clock_sync(local, remote, np.full(50, 6e-4))
    assert sync.offset_s == pytest.approx(123.456, abs=2e-5)
    assert sync.drift == pytest.approx(2e-5, abs=5e-6)
    assert sync.to_local(123.456 + (1 + 2e-5) * 5.0) == pytest.approx(5.0, abs=1e-4)


def test_world_camera_to_head_space() -> None:
    assert world_mm_to_head_m((100.0, -50.0, 800.0)) == pytest.approx((0.1, 0.05, -0.8))


def test_client_syncs_clock_receives_gaze_counts_gaps_and_detects_disconnect() -> None:
    server = FakePupilCapture(offset_s=1000.0, skip_every=10, low_confidence_every=7)
    clock = RealClock()
    client = PupilClient("127.0.0.1", server.port, clock=clock.now_s, n_sync=10, lost_after_s=1.0)
    try:
        started_s = clock.now_s()
        client.start()
        assert client.sync is not None
        # Pupil time = monotonic + 1000; the session clock starts near 0, so the offset is ~1000 + epoch
        local_now = clock.now_s()
        assert client.sync.to_local(server.pupil_time()) == pytest.approx(local_now, abs=0.01)
        wait_until(lambda: client.stats()["samples_received"] > 20 and client.stats()["gaps"] >= 2
                   and client.stats()["low_confidence"] >= 2, what="20 gaze messages, 2 gaps, 2 low-confidence")
        sample = client.latest(clock.now_s())
        assert sample is not None
        assert sample.fixation_m == pytest.approx((0.1, 0.05, -0.8))
        # mapped onto the session clock: sent after the client started, received before now
        assert started_s - 0.01 <= sample.timestamp_s <= clock.now_s() + 0.01
        stats = client.stats()
        assert stats["gaps"] >= 2  # every 10th message withheld
        assert stats["low_confidence"] >= 2
        server.stop()

        def lost() -> bool:
            try:
                client.latest(clock.now_s())
            except TrackerLost as exc:
                assert "no gaze from Pupil" in str(exc)
                return True
            return False

        wait_until(lost, what="TrackerLost after the server stopped")
    finally:
        client.close()
        server.stop()


def test_session_stops_cleanly_when_pupil_disconnects_mid_trial(tmp_path: Path) -> None:
    protocol = load_protocol(fast_protocol(tmp_path, "detection", repetitions=1, phase_s=0.05))
    server = FakePupilCapture()
    data = tmp_path / "data"
    options = SessionOptions(participant="P1", seed=3, tracker=f"pupil:127.0.0.1:{server.port}", clock="real",
                             data_root=data, progress=False, render="cameras")
    # the tracker disconnects once 3 trials are durable (an event, not a wall-clock moment)
    real_append = SessionStore.append_trial

    def append_then_disconnect(self: SessionStore, row, frames, gaze=None) -> None:
        real_append(self, row, frames, gaze)
        if int(row["trial"]) == 2:
            server.stop()

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(SessionStore, "append_trial", append_then_disconnect)
        outcome = run_session(protocol, compile_schedule, options)
    assert outcome.status == "tracker_lost"
    assert "no gaze from Pupil" in outcome.message and "discarded" in outcome.message
    assert outcome.exit_code == 3
    session = data / "detection" / "sub-P1" / "ses-1"
    trials = pd.read_parquet(session / "trials.parquet")
    frames = pd.read_parquet(session / "frames.parquet")
    assert 0 < len(trials) == outcome.n_recorded < 15
    assert trials["trial"].tolist() == list(range(len(trials)))
    assert set(frames["trial"]) == set(trials["trial"])  # every frame of every recorded trial, none of the lost one
    fresh = frames[frames["gaze_valid"]]
    # gaze counts as live up to the 0.1 s staleness limit, applied when the frame takes the sample;
    # sample_age_s is measured later, at flip, so it may exceed the limit by that frame's own time
    # the sample was taken after the previous frame's submit, so age <= limit + time since that submit
    # (typical ages are durations: benchmarks/bench_session_latency.py)
    since_previous_s = frames["submit_s"].diff()
    assert len(fresh) > 50 and (fresh["sample_age_s"] >= 0).all()
    later = fresh.index[fresh.index > 0]
    assert (fresh.loc[later, "sample_age_s"] <= 0.1 + since_previous_s[later] + 1e-9).all()
    # trials finished after the server went silent (before the 1 s loss limit) hold the last gaze, flagged
    held = frames[frames["gaze_held"]]
    assert held[["fixation_x_m", "fixation_y_m", "fixation_z_m"]].notna().all().all()
    import json

    meta = json.loads((session / "session.json").read_text())
    assert meta["status"] == "incomplete"
    assert meta["runs"][0]["clock_sync"]["n"] == 20

    # the tracker is back: resume completes the schedule
    server2 = FakePupilCapture()
    try:
        options2 = SessionOptions(participant="P1", seed=3, tracker=f"pupil:127.0.0.1:{server2.port}", clock="real",
                                  data_root=data, progress=False, render="cameras")
        outcome2 = run_session(protocol, compile_schedule, options2)
    finally:
        server2.stop()
    assert outcome2.status == "complete"
    final = pd.read_parquet(session / "trials.parquet")
    assert final["trial"].tolist() == list(range(15))
    assert math.isfinite(final["drift_correction_deg"].iloc[-1])


def test_capture_binocular_datum_with_integer_eye_keys_is_decoded_over_the_wire() -> None:
    """Capture's binocular 3-D gaze keys its eye maps by the integers 0 and 1; msgpack's default
    strict_map_key refused them, so every such datum was counted malformed. Through a real ZMQ/msgpack round
    trip both eyes now reach the raw stream (eye 1 is the left eye)."""
    import msgpack
    from pupil_server import BINOCULAR_FIELDS

    with pytest.raises(ValueError):  # what the client did before: msgpack's default refuses integer keys
        msgpack.unpackb(msgpack.packb(BINOCULAR_FIELDS, use_bin_type=True), raw=False)
    server = FakePupilCapture(binocular=True)
    clock = RealClock()
    client = PupilClient("127.0.0.1", server.port, clock=clock.now_s, n_sync=5)
    try:
        client.start()
        wait_until(lambda: client.stats()["samples_received"] >= 5, what="5 binocular gaze messages")
        assert client.stats()["malformed"] == 0
        raw = client.drain_raw()
        assert raw and all(s.left is not None and s.right is not None for s in raw)
        assert raw[0].left is not None and raw[0].left.centre_m == pytest.approx((-0.03, -0.01, 0.02))
        assert raw[0].right is not None and raw[0].right.pupil_diameter_mm == 3.1
    finally:
        client.close()
        server.stop()
