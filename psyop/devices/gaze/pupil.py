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
import queue
import threading
import time
from collections.abc import Callable

import msgpack
import numpy as np
import zmq

from psyop.session.rows import JsonObject
from psyop.errors import UserError
from psyop.session.events import SessionEvent
from psyop.session.gaze.plan import FixationPlan
from psyop.session.gaze.sample import EyeSample, GazeSample, RawBuffer, RawGazeSample, TrackerLost, is_usable
from psyop.session.gaze.sync import ClockSync, fit_clock_sync

__all__ = ["ClockSync", "PupilClient", "fit_clock_sync", "head_m_to_world_mm", "world_mm_to_head_m"]


def world_mm_to_head_m(point_mm: tuple[float, float, float]) -> tuple[float, float, float]:
    """Pupil world camera (x right, y down, z forward, mm) -> head space (y up, -z forward, m)."""
    x, y, z = point_mm
    return (x / 1000.0, -y / 1000.0, -z / 1000.0)


def head_m_to_world_mm(point_m: tuple[float, float, float]) -> tuple[float, float, float]:
    """Head space (x right, y up, -z forward, m) -> Pupil's world-camera frame (x right, y down, z forward, mm):
    the inverse of :func:`world_mm_to_head_m`. An HMD calibration's reference points are sent in this frame, so
    the gaze Capture maps after it (in the frame of its reference points) decodes as every Pupil datum does."""
    x, y, z = point_m
    return (x * 1000.0, -y * 1000.0, -z * 1000.0)


def world_to_head_direction(direction: tuple[float, float, float]) -> tuple[float, float, float]:
    """A direction in Pupil's world-camera frame (x right, y down, z forward) in head space."""
    x, y, z = direction
    return (x, -y, -z)


def _triple(value: object) -> tuple[float, float, float] | None:
    if isinstance(value, (list, tuple)) and len(value) >= 3:
        return (float(value[0]), float(value[1]), float(value[2]))
    return None


def _per_eye(payload: JsonObject, plural: str, singular: str, eye_id: int) -> tuple[float, float, float] | None:
    """``eye_centers_3d[eye_id]`` (binocular datum) or ``eye_center_3d`` (monocular datum of that eye)."""
    both = payload.get(plural)
    if isinstance(both, dict):
        return _triple(both.get(eye_id, both.get(str(eye_id))))
    topic = str(payload.get("topic", ""))
    if topic.endswith(f".{eye_id}.") or topic.endswith(f".{eye_id}"):
        return _triple(payload.get(singular))
    return None


def decode_message(frame: bytes) -> JsonObject:
    """One msgpack frame of Pupil's IPC backbone, as Capture encodes it: a binocular datum's ``eye_centers_3d``
    and ``gaze_normals_3d`` are maps keyed by the integers 0 and 1, which msgpack's default ``strict_map_key``
    refuses. Raises msgpack's or ValueError's exceptions on a malformed frame; a frame that is not a map is a
    ValueError."""
    message = msgpack.unpackb(frame, raw=False, strict_map_key=False)
    if not isinstance(message, dict):
        raise ValueError(f"a Pupil message is a map, not {type(message).__name__}")
    return message


def pupil_eyes(payload: JsonObject) -> tuple[EyeSample | None, EyeSample | None]:
    """(left, right) eye parts of a Pupil ``gaze.3d`` datum (Pupil's eye 0 is the right eye,
    eye 1 the left): eyeball centre and gaze normal (world camera -> head space) and the pupil
    diameters of its ``base_data`` pupil data (``diameter_3d`` mm, ``diameter`` px)."""
    diameters: dict[int, tuple[float, float]] = {}
    for datum in payload.get("base_data") or ():
        if isinstance(datum, dict) and datum.get("id") in (0, 1):
            diameters[int(datum["id"])] = (float(datum.get("diameter_3d", math.nan)), float(datum.get("diameter", math.nan)))
    eyes: list[EyeSample | None] = []
    for eye_id in (1, 0):  # left, right
        centre = _per_eye(payload, "eye_centers_3d", "eye_center_3d", eye_id)
        normal = _per_eye(payload, "gaze_normals_3d", "gaze_normal_3d", eye_id)
        if centre is None and normal is None and eye_id not in diameters:
            eyes.append(None)
            continue
        nan3 = (math.nan, math.nan, math.nan)
        mm, px = diameters.get(eye_id, (math.nan, math.nan))
        eyes.append(EyeSample(world_mm_to_head_m(centre) if centre else nan3,
                              world_to_head_direction(normal) if normal else nan3, mm, px))
    return eyes[0], eyes[1]


class PupilClient:
    """A :class:`~psyop.session.gaze.sample.GazeSource` reading gaze from Pupil Capture.

    Two background threads: one receives gaze, one owns Pupil Remote (REQ) and re-runs the
    clock sync every ``resync_every_s``, so a slow or garbled ``t`` reply never delays gaze.
    Each thread polls with a timeout, so ``close`` always joins them.

    Honest failures:
    - ``start`` on an unreachable Pupil Remote raises a UserError with exit code 3 naming
      the address (no traceback).
    - A malformed, NaN or infinite ``t`` reply, and a ``t`` that times out, are counted
      (``sync_malformed``, ``sync_timeouts``) and survived.
    - A gaze sample with a non-finite timestamp or position is an invalid sample; one whose
      time maps more than ``clock_jump_s`` away from now (far future, or a Pupil clock reset)
      is invalid, counted in ``clock_jumps``, logged in ``clock_events`` and triggers a fresh
      resync (old sync pairs dropped).
    - ``latest`` raises :class:`TrackerLost` after ``lost_after_s`` without any gaze message
      ("no gaze"), and separately when no clock sync has succeeded for ``sync_stale_after_s``
      (a multiple of the resync's own request timeout): each message says which it is.
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
        resync_every_s: float = 1.0,
        clock_jump_s: float = 1.0,
        sync_stale_after_s: float | None = None,
        calibrate: bool = False,
        calibration_timeout_s: float = 180.0,
        record_name: str | None = None,
        annotate: bool = False,
    ) -> None:
        self.host, self.port = host, port
        self.calibrate = calibrate
        self.calibration_timeout_s = calibration_timeout_s
        self.record_name = record_name
        self.annotate = annotate
        self.calibration: JsonObject | None = None  # what Capture's calibration said (session.json)
        self.sub_port: int | None = None  # the IPC backbone's subscription port (known once started)
        self._recording = False
        self._annotations: queue.Queue[JsonObject] = queue.Queue()
        self._annotations_sent = self._annotations_confirmed = 0
        self._clock = clock
        self.confidence_threshold = confidence_threshold
        self.n_sync = n_sync
        self.nominal_rate_hz = nominal_rate_hz
        self.lost_after_s = lost_after_s
        self.request_timeout_s = request_timeout_s
        self.resync_every_s = resync_every_s
        self.clock_jump_s = clock_jump_s
        self.sync_stale_after_s = (sync_stale_after_s if sync_stale_after_s is not None
                                   else max(5.0, 3.0 * (resync_every_s + request_timeout_s)))
        self._ctx = zmq.Context()
        self._req: zmq.Socket | None = None
        self._threads: list[threading.Thread] = []
        self._stop = threading.Event()
        self._resync_now = threading.Event()
        self._lock = threading.Lock()
        self._latest: GazeSample | None = None
        self._last_message_local_s = math.nan
        self._last_sync_ok_s = math.nan
        self._last_pupil_t = math.nan
        self._received = self._gaps = self._low_confidence = self._malformed = 0
        self._nonfinite = self._clock_jumps = self._sync_timeouts = self._sync_malformed = self._resyncs = 0
        self._sync_slow = 0
        self._raw = RawBuffer()
        self._events: list[dict[str, float | str]] = []
        self.sync: ClockSync | None = None
        self._pairs: list[tuple[float, float, float]] = []  # (local mid, remote, round trip)

    @property
    def address(self) -> str:
        return f"tcp://{self.host}:{self.port}"

    # connection ----------------------------------------------------------------------
    def _connect_req(self) -> zmq.Socket:
        req = self._ctx.socket(zmq.REQ)
        req.setsockopt(zmq.LINGER, 0)
        # a request that timed out must not wedge the socket; a late reply to it is dropped
        req.setsockopt(zmq.REQ_RELAXED, 1)
        req.setsockopt(zmq.REQ_CORRELATE, 1)
        req.connect(self.address)
        return req

    def _request(self, message: str) -> str | None:
        """The reply, or None when none came within ``request_timeout_s``."""
        assert self._req is not None
        self._req.send_string(message)
        deadline = time.monotonic() + self.request_timeout_s
        while (left_s := deadline - time.monotonic()) > 0:
            if not self._req.poll(max(1, int(left_s * 1000))):
                return None
            try:  # a late reply to an earlier, timed-out request is dropped here (REQ_CORRELATE)
                return self._req.recv(zmq.NOBLOCK).decode("utf-8", errors="replace")
            except zmq.Again:
                continue
        return None

    def _unreachable(self, what: str) -> UserError:
        return UserError(f"Pupil Remote at {self.address} {what}; is Pupil Capture (or Service) running "
                         "with Pupil Remote on this port?", "--tracker", exit_code=3)

    def start(self) -> None:
        self._req = self._connect_req()
        reply = self._request("SUB_PORT")
        if reply is None:
            raise self._unreachable(f"did not answer 'SUB_PORT' within {self.request_timeout_s} s")
        if not reply.isdigit() or not 0 < int(reply) < 65536:
            raise self._unreachable(f"answered 'SUB_PORT' with {reply[:40]!r}, not a port number")
        sub_port = self.sub_port = int(reply)
        self.sync = self.synchronise()
        if self.annotate:  # Capture records annotations only while its Annotation_Capture plugin runs
            self._forward({"subject": "start_plugin", "name": "Annotation_Capture", "args": {},
                           "topic": "notify.start_plugin"})
        if self.calibrate:
            self._run_calibration(sub_port)
        if self.record_name is not None:
            reply = self._request(f"R {self.record_name}")
            if reply != "OK":
                raise self._unreachable(f"answered 'R {self.record_name}' with {str(reply)[:40]!r}, not 'OK'")
            self._recording = True
        sub = self._ctx.socket(zmq.SUB)
        sub.setsockopt(zmq.LINGER, 0)
        sub.connect(f"tcp://{self.host}:{sub_port}")
        sub.setsockopt_string(zmq.SUBSCRIBE, "gaze.3d.")
        self._last_message_local_s = self._clock()
        self._threads = [threading.Thread(target=self._receive, args=(sub,), name="pupil-sub", daemon=True),
                         threading.Thread(target=self._keep_synced, name="pupil-sync", daemon=True)]
        for thread in self._threads:
            thread.start()

    def _forward(self, message: JsonObject) -> bool:
        """Send a multipart message (a ``notify.*`` notification, an annotation) through Pupil Remote,
        which forwards it to the IPC backbone; True when it said so ('Message forwarded.')."""
        assert self._req is not None
        self._req.send_multipart([str(message["topic"]).encode(), msgpack.packb(message, use_bin_type=True)])
        deadline = time.monotonic() + self.request_timeout_s
        while (left_s := deadline - time.monotonic()) > 0:
            if not self._req.poll(max(1, int(left_s * 1000))):
                return False
            try:
                return self._req.recv(zmq.NOBLOCK).decode("utf-8", errors="replace") == "Message forwarded."
            except zmq.Again:
                continue
        return False

    def _run_calibration(self, sub_port: int) -> None:
        """Start Capture's own calibration ('C') and wait for ``calibration.successful`` or
        ``calibration.failed`` (at most ``calibration_timeout_s``); a failure stops the session
        before its first trial (UserError, exit code 3) and is recorded either way."""
        sub = self._ctx.socket(zmq.SUB)
        sub.setsockopt(zmq.LINGER, 0)
        sub.connect(f"tcp://{self.host}:{sub_port}")
        sub.setsockopt_string(zmq.SUBSCRIBE, "notify.calibration.")
        try:
            started_s = self._clock()
            reply = self._request("C")
            if reply != "OK":
                raise self._unreachable(f"answered 'C' (start calibration) with {str(reply)[:40]!r}, not 'OK'")
            outcome: JsonObject | None = None
            while outcome is None and self._clock() - started_s < self.calibration_timeout_s:
                if not sub.poll(100):
                    continue
                parts = sub.recv_multipart()
                try:
                    note = decode_message(parts[1])
                except (IndexError, ValueError, msgpack.UnpackException):
                    continue
                subject = str(note.get("subject", ""))
                if subject in ("calibration.successful", "calibration.failed"):
                    outcome = {"result": subject.rsplit(".", 1)[1], "reason": str(note.get("reason", "")),
                               "duration_s": self._clock() - started_s}
            if outcome is None:
                outcome = {"result": "timeout", "reason": f"no calibration result within {self.calibration_timeout_s:g} s",
                           "duration_s": self._clock() - started_s}
            self.calibration = outcome
        finally:
            sub.close(0)
        if outcome["result"] != "successful":
            raise UserError(f"Pupil Capture's calibration did not succeed ({outcome['result']}: {outcome['reason']}); "
                            "the session did not start: calibrate again and rerun", "--tracker", exit_code=3)

    def annotate_trial(self, trial: int, condition: str, start_s: float, duration_s: float) -> None:
        """Queue one Pupil annotation for a recorded trial (label ``trial``, Pupil time of its start,
        its duration, index and condition); the sync thread sends it through Pupil Remote."""
        sync = self.clock_sync()
        if sync is None:
            return
        self._annotations.put({"topic": "annotation", "label": "trial", "timestamp": sync.to_tracker(start_s),
                               "duration": duration_s, "trial": trial, "condition": condition,
                               "source": "psyop"})

    def emit(self, event: SessionEvent) -> None:
        """:class:`~psyop.session.events.EventSink`: each recorded trial becomes one annotation."""
        if self.annotate and event.kind == "trial_end":
            self.annotate_trial(event.trial, event.condition, event.t_s - event.duration_s, event.duration_s)

    def _send_annotations(self) -> None:
        while True:
            try:
                annotation = self._annotations.get_nowait()
            except queue.Empty:
                return
            confirmed = self._forward(annotation)
            with self._lock:
                self._annotations_sent += 1
                self._annotations_confirmed += int(confirmed)

    def synchronise(self, *, fresh: bool = False) -> ClockSync:
        """Repeated 't' round trips -> least-squares offset (and drift, once they span >= 1 s).

        At least three usable replies are needed (else a UserError, exit code 3).
        """
        if fresh:
            self._pairs.clear()
        good = sum(self._round_trip(reject_slow=False) for _ in range(self.n_sync))
        if good < min(3, self.n_sync):
            raise self._unreachable(f"gave {good} usable clock replies to {self.n_sync} 't' requests "
                                    f"({self._sync_timeouts} timed out, {self._sync_malformed} malformed)")
        return self._fit()

    def _round_trip(self, *, reject_slow: bool = True) -> bool:
        """One 't' request; True when it gave a usable (local, remote) pair.

        During the session a reply that took far longer than usual (queued behind a slow
        one) is not used (``sync_slow``); the initial sync keeps every pair and fits the
        faster half."""
        t0 = self._clock()
        reply = self._request("t")
        t1 = self._clock()
        if reply is None:
            with self._lock:
                self._sync_timeouts += 1
            return False
        try:
            remote = float(reply)
        except ValueError:
            remote = math.nan
        if not math.isfinite(remote):
            with self._lock:
                self._sync_malformed += 1
                self._log_event("malformed 't' reply", reply=reply[:40])
            return False
        mid = 0.5 * (t0 + t1)
        if reject_slow and self._pairs:
            typical_s = float(np.median([trip for _, _, trip in self._pairs]))
            if t1 - t0 > max(0.005, 4.0 * typical_s):  # queued: its mid-point says little about the offset
                with self._lock:
                    self._sync_slow += 1
                return False
        current = self.sync
        if current is not None and abs(current.to_local(remote) - mid) > self.clock_jump_s:
            with self._lock:
                self._clock_jumps += 1
                self._log_event("Pupil clock jumped; old sync pairs dropped", jump_s=current.to_local(remote) - mid)
            self._pairs.clear()
        self._pairs.append((mid, remote, t1 - t0))
        del self._pairs[:-500]
        with self._lock:
            self._last_sync_ok_s = t1
        return True

    def _fit(self) -> ClockSync:
        pairs = np.array(self._pairs)
        return fit_clock_sync(pairs[:, 0], pairs[:, 1], pairs[:, 2])

    def _log_event(self, what: str, **values: float | str) -> None:
        """Record a tracker event (caller holds the lock); the first 50 are kept."""
        if len(self._events) < 50:
            self._events.append({"t_s": self._clock(), "event": what, **values})

    def _keep_synced(self) -> None:
        """The sync thread: owns the REQ socket after start(); never touches gaze."""
        next_sync_s = time.monotonic() + self.resync_every_s
        while not self._stop.is_set():
            requested = self._resync_now.wait(timeout=0.05 if self.annotate else self.resync_every_s)
            if self._stop.is_set():
                break
            self._send_annotations()
            if not requested and time.monotonic() < next_sync_s:
                continue
            next_sync_s = time.monotonic() + self.resync_every_s
            self._resync_now.clear()
            if requested:  # a gaze timestamp far from now: fresh pairs only
                self._pairs.clear()
                with self._lock:
                    self._resyncs += 1
                good = sum(self._round_trip() for _ in range(max(3, self.n_sync // 4)) if not self._stop.is_set())
            else:
                good = int(self._round_trip())
            if good and self._pairs:
                sync = self._fit()
                with self._lock:
                    self.sync = sync

    def _receive(self, sub: zmq.Socket) -> None:
        try:
            while not self._stop.is_set():
                if not sub.poll(50):
                    continue
                parts = sub.recv_multipart()
                self._handle(parts)
        finally:
            sub.close(0)

    def _handle(self, parts: list[bytes]) -> None:
        now = self._clock()
        try:
            payload = decode_message(parts[1])
            pupil_t = float(payload["timestamp"])
            confidence = float(payload.get("confidence", 0.0))
            point = payload.get("gaze_point_3d") or (math.nan, math.nan, math.nan)
            x_mm, y_mm, z_mm = (float(v) for v in point[:3])
            fixation = world_mm_to_head_m((x_mm, y_mm, z_mm))
            left, right = pupil_eyes(payload)
            norm = payload.get("norm_pos") or (math.nan, math.nan)
            norm_pos = (float(norm[0]), float(norm[1]))
        except (IndexError, KeyError, TypeError, ValueError, OverflowError, msgpack.UnpackException):
            with self._lock:
                self._malformed += 1
            return
        with self._lock:
            sync = self.sync
        assert sync is not None
        local_t = sync.to_local(pupil_t) if math.isfinite(pupil_t) else math.nan
        jump = math.isfinite(local_t) and abs(local_t - now) > self.clock_jump_s
        if not math.isfinite(local_t) or jump:
            sample = GazeSample.invalid(now)  # no trustworthy time: never a valid sample
        else:
            sample = GazeSample(local_t, fixation, confidence, is_usable(fixation, confidence, self.confidence_threshold))
        self._raw.add(RawGazeSample(pupil_t, local_t, now, sample.valid, confidence, fixation, norm_pos, left, right))
        with self._lock:
            self._received += 1
            if not math.isfinite(local_t):
                self._nonfinite += 1
            elif jump:
                self._clock_jumps += 1
                self._log_event("gaze timestamp implausible; resync requested", offset_from_now_s=local_t - now)
                self._resync_now.set()
            elif not sample.valid:
                self._low_confidence += 1
            if math.isfinite(pupil_t):
                if math.isfinite(self._last_pupil_t) and 0 < pupil_t - self._last_pupil_t and \
                        pupil_t - self._last_pupil_t > 1.5 / self.nominal_rate_hz and not jump:
                    self._gaps += 1
                self._last_pupil_t = pupil_t
            self._last_message_local_s = now
            self._latest = sample

    # GazeSource ----------------------------------------------------------------------
    def latest(self, now_s: float) -> GazeSample | None:
        with self._lock:
            now = self._clock()
            silent_s = now - self._last_message_local_s
            sync_age_s = now - self._last_sync_ok_s
            sample = self._latest
        if silent_s > self.lost_after_s:
            raise TrackerLost(f"no gaze from Pupil at {self.host}:{self.port} for {silent_s:.1f} s "
                              f"(disconnected?); the session stops here and can be resumed")
        if sync_age_s > self.sync_stale_after_s:
            raise TrackerLost(f"Pupil Remote at {self.host}:{self.port} has not answered a clock-sync 't' request "
                              f"for {sync_age_s:.1f} s (each waits {self.request_timeout_s} s; gaze still arrives), "
                              "so gaze times cannot be mapped to the session clock; the session stops here and can "
                              "be resumed")
        return sample

    def set_plan(self, plan: FixationPlan) -> None:
        """No-op: a real tracker measures where the eye looks."""
        return None

    def clock_sync(self) -> ClockSync | None:
        """The current Pupil-time -> session-clock fit (refitted by the sync thread)."""
        with self._lock:
            return self.sync

    def drain_raw(self) -> list[RawGazeSample]:
        """Every gaze datum received since the last call (malformed messages excepted: counted)."""
        return self._raw.drain()

    def stats(self) -> JsonObject:
        with self._lock:
            return {"samples_received": self._received, "raw_samples_dropped": self._raw.dropped, "gaps": self._gaps,
                    "low_confidence": self._low_confidence, "malformed": self._malformed,
                    "nonfinite_samples": self._nonfinite, "clock_jumps": self._clock_jumps,
                    "sync_timeouts": self._sync_timeouts, "sync_malformed": self._sync_malformed,
                    "sync_slow": self._sync_slow,
                    "resyncs": self._resyncs, "clock_events": list(self._events),
                    "calibration": self.calibration, "recording": self.record_name,
                    "annotations_sent": self._annotations_sent, "annotations_confirmed": self._annotations_confirmed}

    def close(self) -> None:
        self._stop.set()
        self._resync_now.set()
        for thread in self._threads:
            thread.join(timeout=2.0 + self.request_timeout_s)
        if self._req is not None:
            self._send_annotations()  # those queued after the sync thread's last pass
            if self._recording:
                self._recording = self._request("r") != "OK"
        if self._req is not None:
            self._req.close(0)
        self._ctx.term()
