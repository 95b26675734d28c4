"""A small Pupil Capture stand-in speaking the documented Network API over real ZMQ sockets.

Pupil Remote (REP): 'SUB_PORT' -> the PUB port, 't' -> Pupil time as a string.
IPC backbone (PUB): multipart [b'gaze.3d.01.', msgpack map] at ``rate_hz``.
Pupil time = monotonic + ``offset_s`` (+ ``drift`` x elapsed), so the client's clock
sync has something to find. ``skip_every`` drops messages to create gaps.

Faults (plain attributes, changeable while it runs): ``t_delay_s`` delays every 't' reply;
``t_reply`` replaces its text (garbage, 'nan'); ``gaze_time_shift_s`` shifts only the gaze
timestamps (a far-future stream); ``gaze_timestamp`` replaces them (NaN); ``offset_s``
changed mid-run is a Pupil clock reset (both 't' and gaze jump).
"""

from __future__ import annotations

import threading
import time

import msgpack
import zmq


class FakePupilCapture:
    def __init__(self, *, offset_s: float = 1000.0, drift: float = 0.0, rate_hz: float = 120.0,
                 point_mm: tuple[float, float, float] = (100.0, -50.0, 800.0), confidence: float = 0.95,
                 skip_every: int = 0, low_confidence_every: int = 0) -> None:
        self.offset_s, self.drift, self.rate_hz = offset_s, drift, rate_hz
        self.point_mm, self.confidence = point_mm, confidence
        self.skip_every, self.low_confidence_every = skip_every, low_confidence_every
        self.t_delay_s = 0.0
        self.t_reply: str | None = None
        self.gaze_time_shift_s = 0.0
        self.gaze_timestamp: float | None = None
        self.t_requests = 0
        self._ctx = zmq.Context()
        self._rep = self._ctx.socket(zmq.REP)
        self._rep.setsockopt(zmq.LINGER, 0)
        self.port = self._rep.bind_to_random_port("tcp://127.0.0.1")
        self._pub = self._ctx.socket(zmq.PUB)
        self._pub.setsockopt(zmq.LINGER, 0)
        self.sub_port = self._pub.bind_to_random_port("tcp://127.0.0.1")
        self._t0 = time.monotonic()
        self._stop = threading.Event()
        self.sent = 0
        self._threads = [threading.Thread(target=self._serve, daemon=True), threading.Thread(target=self._publish, daemon=True)]
        for t in self._threads:
            t.start()

    def pupil_time(self) -> float:
        now = time.monotonic()
        return now + self.offset_s + self.drift * (now - self._t0)

    def _serve(self) -> None:
        while not self._stop.is_set():
            if not self._rep.poll(20):
                continue
            request = self._rep.recv_string()
            if request == "SUB_PORT":
                self._rep.send_string(str(self.sub_port))
            elif request == "t":
                self.t_requests += 1
                if self.t_delay_s:
                    self._stop.wait(self.t_delay_s)
                self._rep.send_string(self.t_reply if self.t_reply is not None else repr(self.pupil_time()))
            else:
                self._rep.send_string("unknown command")
        self._rep.close(0)

    def _publish(self) -> None:
        period = 1.0 / self.rate_hz
        k = 0
        next_t = time.monotonic()
        while not self._stop.is_set():
            k += 1
            next_t += period
            time.sleep(max(0.0, next_t - time.monotonic()))
            if self.skip_every and k % self.skip_every == 0:
                continue
            confidence = 0.1 if self.low_confidence_every and k % self.low_confidence_every == 0 else self.confidence
            stamp = self.gaze_timestamp if self.gaze_timestamp is not None else self.pupil_time() + self.gaze_time_shift_s
            payload = {"topic": "gaze.3d.01.", "timestamp": stamp, "confidence": confidence,
                       "gaze_point_3d": list(self.point_mm), "norm_pos": [0.5, 0.5]}
            self._pub.send_multipart([b"gaze.3d.01.", msgpack.packb(payload, use_bin_type=True)])
            self.sent += 1
        self._pub.close(0)

    def stop(self) -> None:
        """Disconnect: stop answering and publishing, close the sockets."""
        if self._stop.is_set():
            return
        self._stop.set()
        for t in self._threads:
            t.join(timeout=2.0)
        self._ctx.term()
