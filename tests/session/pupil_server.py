"""A small Pupil Capture stand-in speaking the Network API over real ZMQ sockets.

Pupil Remote (REP), the command set of Capture's ``pupil_remote.py`` with its replies:
'SUB_PORT' / 'PUB_PORT' -> the IPC backbone's ports; 't' -> Pupil time (repr of a float);
'T <time>' -> rebase Pupil time ('Timesync successful.'); 'v' -> the version; 'R [name]' / 'r'
-> recording.should_start / should_stop ('OK'); 'C' / 'c' -> calibration.should_start /
should_stop ('OK'); a multipart message (``notify.*``, ``annotation*``) is forwarded to the
backbone ('Message forwarded.'); anything else 'Unknown command.'.
IPC backbone: a SUB socket bound at PUB_PORT (clients publish there) whose messages are
re-published on the PUB socket at SUB_PORT, as Capture's backbone proxy does; gaze is published
there as multipart [b'gaze.3d.01.', msgpack map] at ``rate_hz``. Acting on notifications like
Capture: ``calibration.should_start`` -> ``calibration.started`` then, after ``calibration_s``,
``calibration.successful`` (or ``calibration.failed`` with a ``reason`` when
``calibration_fails``); ``recording.should_start`` -> ``recording.started`` (with
``session_name``); ``recording.should_stop`` -> ``recording.stopped``. Everything it received is
kept in ``notifications``, ``annotations`` and ``commands`` for the tests to check.
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


#: the eye fields of Capture's binocular 3-D gaze datum ('gaze.3d.01.', Pupil Core Network API, gaze datum
#: format; pupil_src/shared_modules/gaze_mapping/gazer_3d): maps keyed by the eye ids 0 and 1 as integers, and
#: both eyes' pupil data in base_data
BINOCULAR_FIELDS = {"eye_centers_3d": {0: [30.0, 10.0, -20.0], 1: [-30.0, 10.0, -20.0]},
                    "gaze_normals_3d": {0: [0.0, 0.0, 1.0], 1: [0.1, 0.0, 0.995]},
                    "base_data": [{"topic": "pupil.0.3d", "id": 0, "diameter": 41.0, "diameter_3d": 3.1, "confidence": 0.95},
                                  {"topic": "pupil.1.3d", "id": 1, "diameter": 43.0, "diameter_3d": 3.3, "confidence": 0.95}]}


class FakePupilCapture:
    def __init__(self, *, offset_s: float = 1000.0, drift: float = 0.0, rate_hz: float = 120.0,
                 point_mm: tuple[float, float, float] = (100.0, -50.0, 800.0), confidence: float = 0.95,
                 skip_every: int = 0, low_confidence_every: int = 0, binocular: bool = False) -> None:
        self.offset_s, self.drift, self.rate_hz = offset_s, drift, rate_hz
        self.point_mm, self.confidence = point_mm, confidence
        self.skip_every, self.low_confidence_every = skip_every, low_confidence_every
        self.binocular = binocular  # publish Capture's binocular 3-D gaze datum (integer-keyed eye maps)
        self.t_delay_s = 0.0
        self.t_reply: str | None = None
        self.gaze_time_shift_s = 0.0
        self.gaze_timestamp: float | None = None
        self.t_requests = 0
        self.version = "3.5.1"
        self.calibration_s = 0.2
        self.calibration_fails = False
        self.recording: str | None = None
        self.commands: list[str] = []
        self.notifications: list[dict] = []
        self.annotations: list[dict] = []
        self._pub_lock = threading.Lock()
        self._ctx = zmq.Context()
        self._rep = self._ctx.socket(zmq.REP)
        self._rep.setsockopt(zmq.LINGER, 0)
        self.port = self._rep.bind_to_random_port("tcp://127.0.0.1")
        self._pub = self._ctx.socket(zmq.PUB)
        self._pub.setsockopt(zmq.LINGER, 0)
        self.sub_port = self._pub.bind_to_random_port("tcp://127.0.0.1")
        self._backbone_in = self._ctx.socket(zmq.SUB)
        self._backbone_in.setsockopt(zmq.LINGER, 0)
        self._backbone_in.setsockopt(zmq.SUBSCRIBE, b"")
        self.pub_port = self._backbone_in.bind_to_random_port("tcp://127.0.0.1")
        self._t0 = time.monotonic()
        self._stop = threading.Event()
        self.sent = 0
        self._threads = [threading.Thread(target=self._serve, daemon=True), threading.Thread(target=self._publish, daemon=True),
                         threading.Thread(target=self._backbone, daemon=True)]
        for t in self._threads:
            t.start()

    def pupil_time(self) -> float:
        now = time.monotonic()
        return now + self.offset_s + self.drift * (now - self._t0)

    def _send(self, parts: list[bytes]) -> None:
        with self._pub_lock:
            if not self._pub.closed:
                self._pub.send_multipart(parts)

    def _on_message(self, parts: list[bytes]) -> None:
        """A message on the backbone: keep it, re-publish it, act on notifications."""
        topic = parts[0].decode(errors="replace")
        payload = msgpack.unpackb(parts[1], raw=False) if len(parts) > 1 else {}
        if topic.startswith("notify."):
            self.notifications.append(payload)
        elif topic.startswith("annotation"):
            self.annotations.append(payload)
        self._send(parts)
        if topic.startswith("notify."):
            self._act(payload)

    def notify(self, subject: str, **fields: object) -> None:
        payload = {"subject": subject, "topic": f"notify.{subject}", **fields}
        self._on_message([f"notify.{subject}".encode(), msgpack.packb(payload, use_bin_type=True)])

    def _act(self, notification: dict) -> None:
        subject = notification.get("subject")
        if subject == "calibration.should_start":
            self.notify("calibration.started")

            def finish() -> None:
                if self._stop.wait(self.calibration_s):
                    return
                if self.calibration_fails:
                    self.notify("calibration.failed", reason="Not enough ref points or pupil data available for calibration.")
                else:
                    self.notify("calibration.successful")

            threading.Thread(target=finish, daemon=True).start()
        elif subject == "recording.should_start":
            self.recording = str(notification.get("session_name", ""))
            self.notify("recording.started", session_name=self.recording)
        elif subject == "recording.should_stop":
            self.notify("recording.stopped")
            self.recording = None

    def _serve(self) -> None:
        while not self._stop.is_set():
            if not self._rep.poll(20):
                continue
            parts = self._rep.recv_multipart()
            if len(parts) > 1:  # forwarded to the IPC backbone, as Capture does
                self.commands.append(parts[0].decode(errors="replace"))
                self._on_message(parts)
                self._rep.send_string("Message forwarded.")
                continue
            request = parts[0].decode(errors="replace")
            self.commands.append(request)
            if request == "SUB_PORT":
                self._rep.send_string(str(self.sub_port))
            elif request == "PUB_PORT":
                self._rep.send_string(str(self.pub_port))
            elif request == "t":
                self.t_requests += 1
                if self.t_delay_s:
                    self._stop.wait(self.t_delay_s)
                self._rep.send_string(self.t_reply if self.t_reply is not None else repr(self.pupil_time()))
            elif request.startswith("T"):
                try:
                    target = float(request[2:])
                except ValueError:
                    self._rep.send_string(f"'{request[2:]}' cannot be converted to float.")
                    continue
                self.offset_s = target - time.monotonic()
                self._rep.send_string("Timesync successful.")
            elif request == "v":
                self._rep.send_string(self.version)
            elif request.startswith("R"):
                self.notify("recording.should_start", session_name=request[2:])
                self._rep.send_string("OK")
            elif request.startswith("r"):
                self.notify("recording.should_stop")
                self._rep.send_string("OK")
            elif request == "C":
                self.notify("calibration.should_start")
                self._rep.send_string("OK")
            elif request == "c":
                self.notify("calibration.should_stop")
                self._rep.send_string("OK")
            else:
                self._rep.send_string("Unknown command.")
        self._rep.close(0)

    def _backbone(self) -> None:
        while not self._stop.is_set():
            if self._backbone_in.poll(20):
                self._on_message(self._backbone_in.recv_multipart())
        self._backbone_in.close(0)

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
            if self.binocular:
                payload.update(BINOCULAR_FIELDS)
            self._send([b"gaze.3d.01.", msgpack.packb(payload, use_bin_type=True)])
            self.sent += 1
        with self._pub_lock:
            self._pub.close(0)

    def stop(self) -> None:
        """Disconnect: stop answering and publishing, close the sockets."""
        if self._stop.is_set():
            return
        self._stop.set()
        for t in self._threads:
            t.join(timeout=2.0)
        self._ctx.term()
