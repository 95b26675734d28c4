"""Pupil Core Network API client (Pupil Capture / Service).

Wire protocol (docs.pupil-labs.com, "Network API"):
- REQ socket to Pupil Remote (default tcp port 50020). ``'SUB_PORT'`` returns the IPC
  backbone's subscription port; ``'t'`` returns the current Pupil time as a string.
- SUB socket on that port, subscribed to ``'gaze.3d.'``; every message is multipart
  ``[topic, msgpack map]`` with ``timestamp`` (Pupil time, s), ``confidence`` and
  ``gaze_point_3d`` (mm, world-camera frame: x right, y down, z forward).

Clock sync: ``n_sync`` round trips of ``'t'``; each gives (local mid-point, remote
time); a least-squares line remote = offset + (1 + drift) * local maps Pupil time to
the session clock. PUB/SUB drops messages silently, so gaps in the timestamp series
(> 1.5 nominal periods) are counted.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass

import msgpack
import numpy as np
import zmq

from psyop.session.gaze.sample import GazeSample, TrackerLost, is_usable


@dataclass(frozen=True)
class ClockSync:
    """Pupil time = offset_s + (1 + drift) * local time; residual and round trips in s."""

    offset_s: float
    drift: float
    residual_sd_s: float
    round_trip_median_s: float
    n: int

    def to_local(self, pupil_t_s: float) -> float:
        return (pupil_t_s - self.offset_s) / (1.0 + self.drift)

    def as_dict(self) -> dict[str, float]:
        return {"offset_s": self.offset_s, "drift": self.drift, "residual_sd_s": self.residual_sd_s,
                "round_trip_median_s": self.round_trip_median_s, "n": self.n}


def fit_clock_sync(local_mid_s: np.ndarray, remote_s: np.ndarray, round_trips_s: np.ndarray, *,
                   min_span_s: float = 1.0) -> ClockSync:
    """Least-squares line through (local, remote) time pairs.

    Drift is only estimated once the pairs span ``min_span_s``: over a few milliseconds
    of round trips the slope is pure noise. Before that the slope is fixed to 1 and the
    offset is the mean over the faster half of the round trips (least queueing).
    """
    local_mid_s = np.asarray(local_mid_s, dtype=np.float64)
    remote_s = np.asarray(remote_s, dtype=np.float64)
    trips = np.asarray(round_trips_s, dtype=np.float64)
    if local_mid_s.size >= 3 and np.ptp(local_mid_s) >= min_span_s:
        x0 = local_mid_s.mean()
        slope, intercept = np.polyfit(local_mid_s - x0, remote_s, 1)
        offset = intercept - slope * x0
    else:
        fast = trips <= np.median(trips)
        slope, offset = 1.0, float(np.mean((remote_s - local_mid_s)[fast]))
    residual = remote_s - (offset + slope * local_mid_s)
    return ClockSync(float(offset), float(slope - 1.0), float(np.std(residual)), float(np.median(trips)), int(local_mid_s.size))


def world_mm_to_head_m(point_mm: tuple[float, float, float]) -> tuple[float, float, float]:
    """Pupil world camera (x right, y down, z forward, mm) -> head space (y up, -z forward, m)."""
    x, y, z = point_mm
    return (x / 1000.0, -y / 1000.0, -z / 1000.0)


class PupilClient:
    """A :class:`~psyop.session.gaze.sample.GazeSource` reading gaze from Pupil Capture.

    A background thread receives gaze (polling with a timeout, so ``close`` always
    joins it). ``latest`` raises :class:`TrackerLost` after ``lost_after_s`` without a
    message.
    """

    def __init__(
        self,
        host: str,
        port: int = 50020,
        *,
        clock: Callable[[], float],
        confidence_threshold: float = 0.6,
        n_sync: int = 20,
        nominal_rate_hz: float = 120.0,
        lost_after_s: float = 1.0,
        request_timeout_s: float = 2.0,
    ) -> None:
        self.host, self.port = host, port
        self._clock = clock
        self.confidence_threshold = confidence_threshold
        self.n_sync = n_sync
        self.nominal_rate_hz = nominal_rate_hz
        self.lost_after_s = lost_after_s
        self.request_timeout_s = request_timeout_s
        self._ctx = zmq.Context()
        self._req: zmq.Socket | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._latest: GazeSample | None = None
        self._last_message_local_s = math.nan
        self._last_pupil_t = math.nan
        self._received = self._gaps = self._low_confidence = self._malformed = 0
        self.sync: ClockSync | None = None
        self.resync_every_s = 1.0
        self._pairs: list[tuple[float, float, float]] = []  # (local mid, remote, round trip)

    # connection ----------------------------------------------------------------------
    def _request(self, message: str) -> str:
        assert self._req is not None
        self._req.send_string(message)
        if not self._req.poll(int(self.request_timeout_s * 1000)):
            raise TrackerLost(f"Pupil Remote at {self.host}:{self.port} did not answer {message!r} "
                              f"within {self.request_timeout_s} s; is Pupil Capture running?")
        return self._req.recv_string()

    def start(self) -> None:
        self._req = self._ctx.socket(zmq.REQ)
        self._req.setsockopt(zmq.LINGER, 0)
        self._req.connect(f"tcp://{self.host}:{self.port}")
        sub_port = int(self._request("SUB_PORT"))
        self.sync = self.synchronise()
        sub = self._ctx.socket(zmq.SUB)
        sub.setsockopt(zmq.LINGER, 0)
        sub.connect(f"tcp://{self.host}:{sub_port}")
        sub.setsockopt_string(zmq.SUBSCRIBE, "gaze.3d.")
        self._last_message_local_s = self._clock()
        self._thread = threading.Thread(target=self._receive, args=(sub,), name="pupil-sub", daemon=True)
        self._thread.start()

    def synchronise(self) -> ClockSync:
        """Repeated 't' round trips -> least-squares offset (and drift, once they span >= 1 s)."""
        for _ in range(self.n_sync):
            self._round_trip()
        return self._fit()

    def _round_trip(self) -> None:
        t0 = self._clock()
        remote = float(self._request("t"))
        t1 = self._clock()
        self._pairs.append((0.5 * (t0 + t1), remote, t1 - t0))
        del self._pairs[:-500]

    def _fit(self) -> ClockSync:
        pairs = np.array(self._pairs)
        return fit_clock_sync(pairs[:, 0], pairs[:, 1], pairs[:, 2])

    def _receive(self, sub: zmq.Socket) -> None:
        last_sync = self._clock()
        try:
            while not self._stop.is_set():
                if self._clock() - last_sync > self.resync_every_s:
                    last_sync = self._clock()
                    try:  # this thread owns the REQ socket after start()
                        self._round_trip()
                        sync = self._fit()
                        with self._lock:
                            self.sync = sync
                    except TrackerLost:
                        pass  # the gaze stream going silent is what latest() reports
                if not sub.poll(50):
                    continue
                parts = sub.recv_multipart()
                self._handle(parts)
        finally:
            sub.close(0)

    def _handle(self, parts: list[bytes]) -> None:
        now = self._clock()
        try:
            payload = msgpack.unpackb(parts[1], raw=False)
            pupil_t = float(payload["timestamp"])
            confidence = float(payload.get("confidence", 0.0))
            point = payload.get("gaze_point_3d") or (math.nan, math.nan, math.nan)
            fixation = world_mm_to_head_m(tuple(float(v) for v in point[:3]))
        except (IndexError, KeyError, TypeError, ValueError, msgpack.UnpackException):
            with self._lock:
                self._malformed += 1
            return
        assert self.sync is not None
        sample_valid = is_usable(fixation, confidence, self.confidence_threshold)
        sample = GazeSample(self.sync.to_local(pupil_t), fixation, confidence, sample_valid)
        with self._lock:
            self._received += 1
            if not sample_valid:
                self._low_confidence += 1
            if math.isfinite(self._last_pupil_t) and pupil_t - self._last_pupil_t > 1.5 / self.nominal_rate_hz:
                self._gaps += 1
            self._last_pupil_t = max(pupil_t, self._last_pupil_t) if math.isfinite(self._last_pupil_t) else pupil_t
            self._last_message_local_s = now
            self._latest = sample

    # GazeSource ----------------------------------------------------------------------
    def latest(self, now_s: float) -> GazeSample | None:
        with self._lock:
            silent_s = self._clock() - self._last_message_local_s
            sample = self._latest
        if silent_s > self.lost_after_s:
            raise TrackerLost(f"no gaze from Pupil at {self.host}:{self.port} for {silent_s:.1f} s "
                              f"(disconnected?); the session stops here and can be resumed")
        return sample

    def stats(self) -> dict[str, float | int]:
        with self._lock:
            return {"samples_received": self._received, "gaps": self._gaps,
                    "low_confidence": self._low_confidence, "malformed": self._malformed}

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self._req is not None:
            self._req.close(0)
        self._ctx.term()
