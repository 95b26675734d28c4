"""Trackers report faults truthfully (issue 12): real ZMQ sockets (tests/devices/pupil_server.py)
and real ptys; every wait polls with a deadline."""

from __future__ import annotations

import math
import os
import socket
import subprocess
import sys
import threading
import time
import tty
from collections.abc import Callable
from pathlib import Path

import pytest
from pupil_server import FakePupilCapture
from session_helpers import fast_protocol

from psyop.errors import UserError
from psyop.session.clock import RealClock
from psyop.devices.gaze.pupil import PupilClient
from psyop.devices.gaze.serial_source import SerialGazeSource
from psyop.devices.serial_lines import MAX_LINE_BYTES, SerialLineReader

DEADLINE_S = 30.0


def _poll(condition: Callable[[], bool], what: str, during: Callable[[], None] | None = None) -> None:
    deadline = time.monotonic() + DEADLINE_S
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        if during is not None:
            during()
        time.sleep(0.01)


class _Pupil:
    """A fake Pupil Capture and a started client on it."""

    def __init__(self, **client_options: float) -> None:
        self.server = FakePupilCapture(offset_s=1000.0)
        self.clock = RealClock()
        options = {"n_sync": 5, "lost_after_s": 0.5, "request_timeout_s": 0.3, "resync_every_s": 0.1, **client_options}
        self.client = PupilClient("127.0.0.1", self.server.port, clock=self.clock.now_s, **options)  # type: ignore[arg-type]
        self.client.start()
        _poll(lambda: self.client.stats()["samples_received"] > 5, "first gaze")

    def fresh_valid(self) -> bool:
        sample = self.client.latest(self.clock.now_s())
        return sample is not None and sample.valid and abs(self.clock.now_s() - sample.timestamp_s) < 0.05

    def close(self) -> None:
        self.client.close()
        self.server.stop()


@pytest.fixture()
def pupil() -> _Pupil:
    rig = _Pupil()
    yield rig
    rig.close()


def test_a_late_t_reply_does_not_stop_gaze(pupil: _Pupil) -> None:
    """A resync answering late blocked the gaze thread: the session stopped with 'no gaze'."""
    pupil.server.t_delay_s = 1.0
    received = pupil.client.stats()["samples_received"]
    # latest() must neither raise nor go stale while several resyncs time out
    _poll(lambda: pupil.client.stats()["sync_timeouts"] >= 3, "timed-out resyncs",
          during=lambda: pupil.client.latest(pupil.clock.now_s()))
    assert pupil.client.stats()["samples_received"] > received + 50
    assert pupil.fresh_valid()


def test_a_late_t_reply_for_too_long_says_so() -> None:
    rig = _Pupil(sync_stale_after_s=0.5)
    try:
        rig.server.t_delay_s = 5.0
        from psyop.session.gaze.sample import TrackerLost

        def raised() -> bool:
            try:
                rig.client.latest(rig.clock.now_s())
            except TrackerLost as exc:
                assert "clock-sync" in str(exc) and "gaze still arrives" in str(exc)
                return True
            return False

        _poll(raised, "the sync to be reported stale")
    finally:
        rig.close()


@pytest.mark.parametrize("reply", ["garbage", "nan", "inf", ""])
def test_a_malformed_t_reply_is_counted_and_survived(pupil: _Pupil, reply: str) -> None:
    pupil.server.t_reply = reply
    _poll(lambda: pupil.client.stats()["sync_malformed"] >= 3, "malformed replies counted",
          during=lambda: pupil.client.latest(pupil.clock.now_s()))
    assert all(thread.is_alive() for thread in pupil.client._threads)
    assert pupil.client.sync is not None and math.isfinite(pupil.client.sync.offset_s)
    assert pupil.fresh_valid()
    pupil.server.t_reply = None
    _poll(pupil.fresh_valid, "gaze after the replies are good again")


def test_nan_gaze_timestamps_are_invalid_samples(pupil: _Pupil) -> None:
    """NaN timestamps made every frame valid with a NaN sample time."""
    pupil.server.gaze_timestamp = math.nan
    _poll(lambda: pupil.client.stats()["nonfinite_samples"] >= 5, "NaN samples counted")
    sample = pupil.client.latest(pupil.clock.now_s())
    assert sample is not None and not sample.valid and math.isfinite(sample.timestamp_s)


def test_future_timestamps_are_invalid_logged_and_trigger_a_resync(pupil: _Pupil) -> None:
    """Timestamps far in the future were never stale."""
    pupil.server.gaze_time_shift_s = 100.0
    _poll(lambda: pupil.client.stats()["resyncs"] >= 1, "a resync")
    stats = pupil.client.stats()
    assert stats["clock_jumps"] >= 1
    assert any("implausible" in event["event"] for event in stats["clock_events"])
    sample = pupil.client.latest(pupil.clock.now_s())
    assert sample is not None and not sample.valid
    pupil.server.gaze_time_shift_s = 0.0
    _poll(pupil.fresh_valid, "valid gaze once the timestamps are sane")


def test_a_pupil_clock_reset_is_followed_by_a_fresh_sync(pupil: _Pupil) -> None:
    """A Pupil clock reset left every later trial with 0 % valid gaze and no warning."""
    pupil.server.offset_s -= 5000.0  # Pupil restarted its clock: 't' and gaze both jump
    _poll(lambda: pupil.client.stats()["clock_jumps"] >= 1, "the jump to be noticed")
    _poll(pupil.fresh_valid, "valid, correctly timed gaze after the resync")
    assert pupil.client.sync is not None
    assert pupil.client.sync.to_local(pupil.server.pupil_time()) == pytest.approx(pupil.clock.now_s(), abs=0.02)


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def test_unreachable_pupil_is_exit_3_with_the_address() -> None:
    port = _free_port()
    client = PupilClient("127.0.0.1", port, clock=RealClock().now_s, request_timeout_s=0.3)
    try:
        with pytest.raises(UserError) as info:
            client.start()
    finally:
        client.close()
    assert info.value.exit_code == 3 and f"127.0.0.1:{port}" in str(info.value)


def test_unreachable_pupil_from_the_command_line(tmp_path: Path) -> None:
    """Pupil not running gave a traceback and exit 1."""
    port = _free_port()
    protocol = fast_protocol(tmp_path, "detection", 1, 0.03)
    result = subprocess.run([sys.executable, "-m", "psyop", "run", str(protocol), "--participant", "P1",
                             "--data", str(tmp_path / "data"), "--tracker", f"pupil:127.0.0.1:{port}",
                             "--clock", "real", "--no-progress", "--render", "cameras"],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 3, result.stderr
    assert f"127.0.0.1:{port}" in result.stderr and "Traceback" not in result.stderr


# -- serial -----------------------------------------------------------------------------

class _Pty:
    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            view = view[os.write(self.master, view):]

    def close(self) -> None:
        os.close(self.master)
        os.close(self.slave)


def test_an_over_long_line_is_discarded_whole() -> None:
    """A line over 256 bytes had its tail parsed as a gaze sample (38 frames at x = 9 m)."""
    device = _Pty()
    lines: list[str] = []
    lock = threading.Lock()

    def on_line(text: str, arrival_s: float) -> bool:
        with lock:
            lines.append(text)
        return True

    reader = SerialLineReader(device.path, on_line, RealClock().now_s)
    try:
        reader.start()
        for length in (MAX_LINE_BYTES + 1, 3 * MAX_LINE_BYTES, 10 * MAX_LINE_BYTES):
            head = b"X" * (length - len(b"G 9 0 -1 0.99"))
            device.write(head + b"G 9 0 -1 0.99\n")
        device.write(b"G 0.01 0.02 -0.5 0.9\n")
        _poll(lambda: bool(lines), "the line after the long ones")
        with lock:
            assert lines == ["G 0.01 0.02 -0.5 0.9"]
        assert reader.garbage == 3
    finally:
        reader.close()
        device.close()


@pytest.mark.parametrize("line", [b"G 1e308 0 -1 0.99\n", b"G nan 0 -1 0.99\n", b"G 0 inf -1 0.99\n",
                                  b"G 1e6 0 -1 0.99\n"])
def test_non_finite_or_absurd_serial_positions_are_invalid(line: bytes) -> None:
    """`G 1e308 ...` marked frames valid with a NaN fixation."""
    device = _Pty()
    clock = RealClock()
    source = SerialGazeSource(device.path, clock=clock.now_s)
    try:
        source.start()
        device.write(line)
        _poll(lambda: source.latest(clock.now_s()) is not None, "the sample")
        sample = source.latest(clock.now_s())
        assert sample is not None and not sample.valid
    finally:
        source.close()
        device.close()


def test_trials_with_little_valid_gaze_are_listed_and_warned(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A Pupil clock fault left trials with 0 % valid gaze and no warning."""
    import json

    import psyop.run.runner  # noqa: F401 - before capsys swaps sys.stderr
    from psyop.cli import main as cli_main

    protocol = fast_protocol(tmp_path, "detection", 1, 0.03)
    server = FakePupilCapture()
    try:
        server.gaze_time_shift_s = 100.0  # every gaze time implausible: every frame invalid
        code = cli_main(["run", str(protocol), "--participant", "G1", "--data", str(tmp_path / "data"),
                         "--tracker", f"pupil:127.0.0.1:{server.port}", "--clock", "real", "--no-progress",
                         "--render", "cameras"])
    finally:
        server.stop()
    err = capsys.readouterr().err
    meta = json.loads((tmp_path / "data" / "detection" / "sub-G1" / "ses-1" / "session.json").read_text())
    assert code == 0, err
    assert meta["integrity"]["low_gaze_trials"] == list(range(15))
    assert "warning: 15 trials had less than 50% valid gaze" in err
    assert meta["summary"]["tracker"]["clock_jumps"] > 0
