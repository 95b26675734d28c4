"""Serial backends through a real pty pair: gaze lines with garbage, and a response box."""

from __future__ import annotations

import os
import select
import threading
import time
import tty
from pathlib import Path

import pandas as pd
import pytest
from session_helpers import fast_protocol, wait_until

from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.session.clock import RealClock
from psyop.devices.gaze.serial_source import SerialGazeSource, parse_gaze_line
from psyop.protocol.kinds import kind_named
from psyop.devices.responses.serial_box import SerialResponseBox
from psyop.run.runner import SessionOptions, run_session

GARBAGE = [b"\xff\xfe\x00garbage\x81\n", b"G 0.1 nan\n", b"G a b c d\n", b"\x00" * 300, b"XYZ 1 2 3 4\n", b"G 0.1 0.0 -1.0\n"]


class PtyDevice:
    """The device end of a pty: a writer thread streams lines; every loop waits with select."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)  # no echo, no line discipline
        self.path = os.ttyname(self.slave)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.lines_sent = 0
        self.garbage_sent = 0

    def stream_gaze(self, rate_hz: float = 240.0, garbage_every: int = 5) -> None:
        def run() -> None:
            k = 0
            while not self._stop.is_set():
                k += 1
                _, writable, _ = select.select([], [self.master], [], 0.05)
                if not writable:
                    continue
                if garbage_every and k % garbage_every == 0:
                    os.write(self.master, GARBAGE[k % len(GARBAGE)])
                    self.garbage_sent += 1
                else:
                    os.write(self.master, "G 0.05 -0.02 -0.9 0.97\r\n".encode())
                    self.lines_sent += 1
                time.sleep(1.0 / rate_hz)

        self._thread = threading.Thread(target=run, daemon=True)
        self._thread.start()

    def write(self, data: bytes) -> None:
        os.write(self.master, data)

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        os.close(self.master)
        os.close(self.slave)


def test_parse_gaze_line_accepts_only_well_formed_lines() -> None:
    assert parse_gaze_line("G 0.1 0.2 -1.0 0.9") == ((0.1, 0.2, -1.0), 0.9)
    assert parse_gaze_line("G,0.1,0.2,-1.0,0.9") == ((0.1, 0.2, -1.0), 0.9)
    for bad in ["", "G", "G 1 2 3", "H 1 2 3 4", "G a b c d", "G 1 2 3 nan", "G 1 2 3 4 5"]:
        assert parse_gaze_line(bad) is None


def test_serial_gaze_survives_garbage_bytes() -> None:
    device = PtyDevice()
    clock = RealClock()
    source = SerialGazeSource(device.path, clock=clock.now_s, latency_s=0.004)
    try:
        source.start()
        device.stream_gaze()
        wait_until(lambda: source.stats()["lines"] > 30 and source.stats()["garbage"] >= 5,
                   what="30 gaze lines and 5 garbage lines")
        sample = source.latest(clock.now_s())
        assert sample is not None and sample.valid
        assert sample.fixation_m == pytest.approx((0.05, -0.02, -0.9))
        stats = source.stats()
        assert stats["lines"] > 30
        assert stats["garbage"] >= 5  # counted and skipped
    finally:
        source.close()
        device.close()


def test_session_with_serial_tracker_and_garbage_completes(tmp_path: Path) -> None:
    protocol = load_protocol(fast_protocol(tmp_path, "detection", repetitions=1, phase_s=0.03))
    device = PtyDevice()
    device.stream_gaze(garbage_every=3)
    try:
        options = SessionOptions(participant="P1", seed=5, tracker=f"serial:{device.path}", clock="real",
                                 data_root=tmp_path / "data", progress=False, render="cameras")
        outcome = run_session(protocol, compile_schedule, options)
    finally:
        device.close()
    assert outcome.status == "complete", outcome.message
    session = tmp_path / "data" / "detection" / "sub-P1" / "ses-1"
    frames = pd.read_parquet(session / "frames.parquet")
    assert frames["gaze_valid"].mean() > 0.5  # garbage lines are skipped, not fatal (freshness under load varies)
    assert frames[["fixation_x_m", "fixation_y_m", "fixation_z_m"]].notna().all().all()
    assert len(pd.read_parquet(session / "trials.parquet")) == 15


def test_serial_response_box_maps_buttons_and_skips_garbage() -> None:
    device = PtyDevice()
    clock = RealClock()
    box = SerialResponseBox(device.path, kind_named("two_interval"), clock=clock.now_s)
    row = {"correct_interval": 2}
    try:
        assert box.collect(row, clock.now_s()) is None  # prompt shown
        device.write(b"\xfe\xffB9\nnoise\nB2\n")
        response = wait_until(lambda: box.collect(row, clock.now_s()), what="the button press")
        assert response.response == "2" and response.correct is True
        assert 0 <= response.response_time_s <= clock.now_s()
        assert box.stats()["garbage"] >= 2
    finally:
        box.close()
        device.close()
