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
HMD calibration as Capture's HMD 3D choreography does it (calibration_choreography/hmd_plugin.py; the plugin is
``HMD3DChoreographyPlugin`` from version 2.0 on, ``HMD_Calibration_3D`` before): ``start_plugin`` of that name
selects it; then ``calibration.should_start`` needs ``translation_eye0`` / ``translation_eye1`` (3 values each)
and answers ``calibration.started``; while it runs the participant's pupil data is collected (``eyes``, where the
test says they look: pupil_hmd_model.Eyes) and every ``calibration.add_ref_data`` ``ref_data`` is kept;
``calibration.should_stop`` answers ``calibration.stopped``, fits the mapping (pupil_hmd_model.HmdCalibration.fit)
and answers ``calibration.successful`` then ``calibration.result.v2``, or ``calibration.failed`` with reason
``CalibrationError`` (Capture >= 2.0's words; ``hmd_failure`` keeps the cause). Once fitted, gaze is the fitted
mapping of where the eyes look (the reference frame, mm), binocular fields included. A test in another process
moves the eyes with a notification of its own, ``test.look_at`` (``point_m``: head space, m; ``delay_s``: from
now, in Pupil time), which Capture would ignore.
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
import numpy as np
import zmq
from pupil_hmd_model import Eyes, HmdCalibration, HmdFit


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
                 skip_every: int = 0, low_confidence_every: int = 0, binocular: bool = False,
                 version: str = "3.5.1") -> None:
        self.offset_s, self.drift, self.rate_hz = offset_s, drift, rate_hz
        self.point_mm, self.confidence = point_mm, confidence
        self.skip_every, self.low_confidence_every = skip_every, low_confidence_every
        self.binocular = binocular  # publish Capture's binocular 3-D gaze datum (integer-keyed eye maps)
        self.t_delay_s = 0.0
        self.t_reply: str | None = None
        self.gaze_time_shift_s = 0.0
        self.gaze_timestamp: float | None = None
        self.t_requests = 0
        self.version = version
        self.calibration_s = 0.2
        self.calibration_fails = False
        self.recording: str | None = None
        self.eyes = Eyes()  # where the participant looks (the test moves it); their pupil data feeds an HMD calibration
        self.hmd_plugin: str | None = None  # the HMD calibration plugin started ('start_plugin'), None: none
        self.hmd: HmdCalibration | None = None  # the HMD calibration running
        self.hmd_refs: list[dict] = []  # every reference datum the last HMD calibration received
        self.hmd_fit: HmdFit | None = None  # the mapping the last successful one fitted (gaze follows it)
        self.hmd_failure: str | None = None  # why the last one failed
        self.hmd_max_residual_deg = 1.0
        self._hmd_lock = threading.Lock()
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

    def hmd_plugin_name(self) -> str:
        """The HMD 3-D calibration plugin's name in this Capture version."""
        return "HMD3DChoreographyPlugin" if int(self.version.split(".")[0]) >= 2 else "HMD_Calibration_3D"

    def _act_hmd(self, notification: dict) -> bool:
        """The HMD calibration's part of acting on a notification; True when it was one of its."""
        subject = notification.get("subject")
        if subject == "start_plugin" and notification.get("name") == self.hmd_plugin_name():
            self.hmd_plugin = self.hmd_plugin_name()
            return True
        if self.hmd_plugin is None:
            return False
        if subject == "calibration.should_start":
            t0, t1 = notification.get("translation_eye0"), notification.get("translation_eye1")
            if self.hmd is None and isinstance(t0, list) and isinstance(t1, list) and len(t0) == len(t1) == 3:
                with self._hmd_lock:
                    self.hmd = HmdCalibration((np.asarray(t0, dtype=float), np.asarray(t1, dtype=float)))
                self.notify("calibration.started")
            return True  # without both translations Capture logs an error and does not start
        if subject == "calibration.add_ref_data":
            if self.hmd is not None:
                with self._hmd_lock:
                    self.hmd.refs.extend(notification.get("ref_data") or [])
            return True
        if subject == "calibration.should_stop" and self.hmd is not None:
            with self._hmd_lock:
                hmd, self.hmd = self.hmd, None
            self.hmd_refs = list(hmd.refs)
            self.notify("calibration.stopped")
            fit = hmd.fit(self.rate_hz, self.hmd_max_residual_deg)
            gazer = {"gazer_class_name": "GazerHMD3D", "timestamp": self.pupil_time(), "record": True}
            if isinstance(fit, str):
                self.hmd_failure = fit
                self.notify("calibration.failed", reason="CalibrationError", **gazer)
            else:
                self.hmd_fit, self.hmd_failure = fit, None
                self.notify("calibration.successful", **gazer)
                if self.hmd_plugin == "HMD3DChoreographyPlugin":  # Capture >= 2.0's gazer_base; 1.x sends none
                    self.notify("calibration.result.v2", params=fit.params(), version=2, **gazer)
            return True
        return subject in ("calibration.should_stop",)

    def _act(self, notification: dict) -> None:
        subject = notification.get("subject")
        if subject == "test.look_at":  # the participant of a test in another process (a headset session)
            point = tuple(float(v) for v in notification["point_m"])
            self.eyes.look_from(self.pupil_time() + float(notification.get("delay_s", 0.0)), point)  # type: ignore[arg-type]
            return
        if self._act_hmd(notification):
            return
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
            payload.update(self._hmd_gaze(stamp))
            self._send([b"gaze.3d.01.", msgpack.packb(payload, use_bin_type=True)])
            self.sent += 1
        with self._pub_lock:
            self._pub.close(0)

    def _hmd_gaze(self, stamp: float) -> dict:
        """Collect the eyes' pupil data for an HMD calibration running; once one fitted, the gaze fields it maps."""
        self.eyes.at(stamp)
        normals = self.eyes.pupil_normals()
        with self._hmd_lock:
            if self.hmd is not None:
                self.hmd.pupil.append((float(stamp), normals[0], normals[1]))
            fit = self.hmd_fit
        return fit.gaze(normals) if fit is not None else {}

    def stop(self) -> None:
        """Disconnect: stop answering and publishing, close the sockets."""
        if self._stop.is_set():
            return
        self._stop.set()
        for t in self._threads:
            t.join(timeout=2.0)
        self._ctx.term()
