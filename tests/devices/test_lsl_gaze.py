"""`--tracker lsl:NAME` against real LSL outlets (pylsl, liblsl on loopback)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pylsl
import pytest
from lsl_outlets import PupilRelayOutlet, known_path
from session_helpers import fast_protocol, wait_until

from psyop.errors import UserError
from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.session.clock import RealClock
from psyop.devices.gaze.lsl import LslGazeSource
from psyop.devices.gaze.lsl_channels import BUILT_IN, SceneCamera, detect_map, parse_map
from psyop.devices.gaze.pupil import world_mm_to_head_m, world_to_head_direction
from psyop.session.gaze.sample import TrackerLost
from psyop.session.log.layout import session_paths
from psyop.session.log.store import SessionStore
from psyop.run.runner import SessionOptions, run_session

pytestmark = pytest.mark.timeout(180)


def _unique(name: str, tmp_path: Path) -> str:
    """A stream name no other test (or xdist worker) publishes."""
    return f"{name}_{abs(hash(str(tmp_path))) % 10**8}"


def _expected_row(k: int) -> dict[str, float]:
    v = known_path(k)
    fixation = world_mm_to_head_m((v[3], v[4], v[5]))
    right_c, left_c = world_mm_to_head_m(tuple(v[6:9])), world_mm_to_head_m(tuple(v[9:12]))
    right_n, left_n = world_to_head_direction(tuple(v[12:15])), world_to_head_direction(tuple(v[15:18]))
    return {"gaze_confidence": v[0], "norm_pos_x": v[1], "norm_pos_y": v[2],
            **{f"fixation_{a}_m": fixation[i] for i, a in enumerate("xyz")},
            **{f"eye_centre_right_{a}_m": right_c[i] for i, a in enumerate("xyz")},
            **{f"eye_centre_left_{a}_m": left_c[i] for i, a in enumerate("xyz")},
            **{f"gaze_normal_right_{a}": right_n[i] for i, a in enumerate("xyz")},
            **{f"gaze_normal_left_{a}": left_n[i] for i, a in enumerate("xyz")},
            "pupil_diameter_right_px": v[18], "pupil_diameter_left_px": v[19],
            "pupil_diameter_right_mm": v[20], "pupil_diameter_left_mm": v[21]}


def test_session_logs_the_pupil_relay_stream_in_full_and_on_the_session_clock(tmp_path: Path) -> None:
    name = _unique("pupil_capture", tmp_path)
    outlet = PupilRelayOutlet(name)
    try:
        protocol = load_protocol(fast_protocol(tmp_path, "realism", repetitions=1, phase_s=0.05))
        data = tmp_path / "data"
        options = SessionOptions(participant="P1", seed=2, tracker=f"lsl:{name}", clock="real", data_root=data,
                                 progress=False, render="cameras")
        outcome = run_session(protocol, compile_schedule, options)
        assert outcome.status == "complete", outcome.message
        sent = dict((stamp, k) for k, stamp in outlet.sent())
    finally:
        outlet.close()
    paths = session_paths(data, protocol.study.name, "P1", 1)
    meta = json.loads(paths.metadata.read_text())
    gaze = pd.read_parquet(paths.gaze_parquet)
    frames = pd.read_parquet(paths.frames_parquet)
    # the raw stream in full: every sample pushed from the first received to the last, once, in order
    ks = [sent[t] for t in gaze["tracker_t_s"]]
    assert len(ks) > 100 and ks == list(range(ks[0], ks[-1] + 1))
    # ... each exactly as sent (channels mapped by label, world camera -> head space)
    expected = pd.DataFrame([_expected_row(k) for k in ks])
    for column in expected.columns:
        np.testing.assert_allclose(gaze[column].to_numpy(), expected[column].to_numpy(), rtol=0, atol=1e-12,
                                   err_msg=column)
    blinks = np.array([k % 50 == 49 for k in ks])
    assert not gaze["gaze_valid"][blinks].any() and gaze["gaze_valid"][~blinks].all()
    # ... on the session clock through the recorded time_correction() sync
    assert "NaN" not in paths.metadata.read_text()  # strict JSON
    sync = meta["runs"][0]["clock_sync"]
    assert sync["method"] == "lsl-time-correction" and sync["round_trip_median_s"] is None
    mapped = gaze["tracker_t_s"] - sync["offset_s"]
    assert np.abs(gaze["gaze_sample_t_s"] - mapped).max() < 2e-3  # later resyncs move it by microseconds
    assert (gaze["received_s"] >= gaze["gaze_sample_t_s"] - 1e-3).all()  # received after it was stamped
    # every frame used one of these samples, at the time the raw stream gives it
    used = frames.loc[~frames["gaze_held"], "gaze_sample_t_s"]
    assert len(used) > 20 and set(used) <= set(gaze["gaze_sample_t_s"])
    tracker = meta["summary"]["tracker"]
    assert tracker["channel_map"] == "pupil_capture" and tracker["samples_received"] == len(gaze)
    assert tracker["invalid_fixation"] == int(blinks.sum())
    stamps = gaze["tracker_t_s"].to_numpy()
    assert tracker["gaps"] == int((np.diff(stamps) > 1.5 / outlet.rate_hz).sum())  # counted, never hidden
    assert tracker["reconnects"] == 0 and tracker["clock_sync_end"]["method"] == "lsl-time-correction"


def test_a_lost_stream_stops_the_session_cleanly_with_every_sample_kept(tmp_path: Path) -> None:
    name = _unique("pupil_capture", tmp_path)
    outlet = PupilRelayOutlet(name)
    protocol = load_protocol(fast_protocol(tmp_path, "detection", repetitions=1, phase_s=0.05))
    data = tmp_path / "data"
    options = SessionOptions(participant="P1", seed=3, tracker=f"lsl:{name}", clock="real", data_root=data,
                             progress=False, render="cameras")
    real_append = SessionStore.append_trial

    def append_then_close(self: SessionStore, row, frames, gaze=None) -> None:  # type: ignore[no-untyped-def]
        real_append(self, row, frames, gaze)
        if int(row["trial"]) == 1:
            outlet.close()

    try:
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(SessionStore, "append_trial", append_then_close)
            outcome = run_session(protocol, compile_schedule, options)
    finally:
        outlet.close()
    assert outcome.status == "tracker_lost" and outcome.exit_code == 3
    assert "no gaze from LSL stream" in outcome.message
    paths = session_paths(data, protocol.study.name, "P1", 1)
    trials = pd.read_parquet(paths.trials_parquet)
    n = len(trials)  # trials that ended within lost_after_s of the loss are recorded (their gaze held, flagged)
    assert n >= 2 and trials["trial"].tolist() == list(range(n)) and n < 15
    gaze = pd.read_parquet(paths.gaze_parquet)
    sent = [stamp for _, stamp in outlet.sent()]
    first = sent.index(gaze["tracker_t_s"].iloc[0])
    received = gaze["tracker_t_s"].tolist()
    assert received == sent[first:first + len(received)]  # every sample received, once, in order
    # only what was still in flight when the outlet was destroyed (liblsl drops it) is missing
    assert sent[-1] - received[-1] < 0.25
    meta = json.loads(paths.metadata.read_text())
    assert meta["status"] == "incomplete" and meta["summary"]["tracker"]["lost"] == 1
    assert meta["summary"]["tracker"]["reconnects"] == 0


def test_gaps_and_reconnects_are_counted(tmp_path: Path) -> None:
    name = _unique("gapped", tmp_path)
    clock = RealClock()
    source_id = f"psyop-test-{name}"
    from lsl_outlets import pupil_relay_info

    def outlet() -> pylsl.StreamOutlet:
        info = pupil_relay_info(name, 100.0)
        fresh = pylsl.StreamInfo(name, "Gaze", info.channel_count(), 100.0, pylsl.cf_double64, source_id)
        fresh.desc().append_child("channels")
        channels = fresh.desc().child("channels")
        src = info.desc().child("channels").child("channel")
        while not src.empty():
            c = channels.append_child("channel")
            c.append_child_value("label", src.child_value("label"))
            c.append_child_value("eye", src.child_value("eye"))
            src = src.next_sibling("channel")
        return pylsl.StreamOutlet(fresh)

    first = outlet()
    gaze = LslGazeSource(name, clock=clock.now_s, lost_after_s=30.0)
    try:
        def push(o: pylsl.StreamOutlet, t0: float, n: int, skip: range = range(0)) -> None:
            for k in range(n):
                if k not in skip:
                    o.push_sample(known_path(k), t0 + k / 100.0)

        wait_until(lambda: pylsl.resolve_byprop("name", name, 1, 0.2), what="the outlet to be visible")
        gaze.start()
        wait_until(first.have_consumers, what="the inlet to connect")
        t0 = pylsl.local_clock()
        push(first, t0, 60, skip=range(20, 40))  # 20 samples (0.2 s) never sent
        wait_until(lambda: gaze.stats()["samples_received"] >= 40, what="40 samples")
        stats = gaze.stats()
        assert stats["gaps"] == 1 and stats["gap_s"] == pytest.approx(0.2, abs=1e-6)
        del first  # the outlet goes away: the inlet sees the stream lost
        wait_until(lambda: gaze.stats()["lost"] == 1, what="the loss to be noticed")
        assert gaze.stats()["reconnects"] == 0
        second = outlet()  # the same source comes back
        wait_until(lambda: second.have_consumers(), what="the inlet to reconnect")
        push(second, pylsl.local_clock(), 10)
        wait_until(lambda: gaze.stats()["samples_received"] >= 50, what="samples after the reconnect")
        assert gaze.stats()["reconnects"] == 1 and gaze.stats()["lost"] == 1  # counted once data came back
        events = [e["event"] for e in gaze.stats()["events"]]
        assert "LSL stream lost; waiting for its source to come back" in events and "LSL stream reconnected" in events
    finally:
        gaze.close()


def test_no_stream_is_a_clear_error() -> None:
    clock = RealClock()
    source = LslGazeSource("psyop_no_such_stream_xyz", clock=clock.now_s, resolve_timeout_s=0.3)
    with pytest.raises(UserError) as info:
        source.start()
    assert info.value.exit_code == 3 and "no LSL stream named" in str(info.value)
    source.close()


def test_silence_is_tracker_lost(tmp_path: Path) -> None:
    name = _unique("silent", tmp_path)
    outlet = PupilRelayOutlet(name)
    clock = RealClock()
    source = LslGazeSource(name, clock=clock.now_s, lost_after_s=0.3)
    try:
        source.start()
        wait_until(lambda: source.stats()["samples_received"] > 5, what="samples")
        outlet._paused.set()

        def lost() -> bool:
            try:
                source.latest(clock.now_s())
            except TrackerLost as exc:
                return "no gaze from LSL stream" in str(exc)
            return False

        wait_until(lost, what="TrackerLost after silence")
    finally:
        source.close()
        outlet.close()


def test_built_in_maps_are_detected_from_the_labels() -> None:
    from lsl_outlets import PUPIL_RELAY_CHANNELS

    pupil = [(label, eye) for label, eye, _, _ in PUPIL_RELAY_CHANNELS]
    assert len(pupil) == 22 and detect_map(pupil) is BUILT_IN["pupil_capture"]
    neon = [("x", None), ("y", None), *((f"{c}", eye) for eye in ("left", "right")
                                           for c in ("PupilDiameter", "EyeballCenterX", "EyeballCenterY",
                                                     "EyeballCenterZ", "OpticalAxisX", "OpticalAxisY", "OpticalAxisZ"))]
    neon_map = detect_map(neon)
    assert neon_map is BUILT_IN["neon"]
    index = neon_map.resolve(neon, "neon")
    assert index["pupil_diameter_right_mm"] == 9 and index["gaze_normal_left_z"] == 8  # same label, told apart by eye
    assert detect_map([("a", None)]) is None
    with pytest.raises(UserError, match="needs channels for"):
        BUILT_IN["pupil_capture"].resolve([("confidence", None)], "stream")


def test_scene_pixel_pinhole_and_map_file_errors() -> None:
    camera = SceneCamera(1600.0, 1200.0, 103.0, 77.0)
    assert camera.direction_world(800.0, 600.0) == pytest.approx((0.0, 0.0, 1.0))
    x, _, z = camera.direction_world(1600.0, 600.0)  # the right edge: half the horizontal field of view
    assert math.degrees(math.atan2(x, z)) == pytest.approx(51.5)
    for raw, says in [({"fixation": "eyes"}, "'fixation' must be one of"),
                      ({"fixation": "head_m", "roles": {"gaze_point_x": "a"}}, "needs the roles"),
                      ({"fixation": "head_m", "roles": {"nonsense": "a"}}, "unknown role"),
                      ({"fixation": "scene_px", "roles": {"scene_x_px": "x", "scene_y_px": "y"}}, "needs 'scene'"),
                      ([], "JSON object")]:
        with pytest.raises(UserError, match=says):
            parse_map(raw, "map.json")
