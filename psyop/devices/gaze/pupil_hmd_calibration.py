"""In-headset calibration of Pupil Core through Pupil Capture's HMD calibration, over Pupil Remote.

The :class:`~psyop.session.headset_calibration.HeadsetCalibration` of ``--tracker pupil:HOST:PORT,calibrate-hmd``.
psyop shows the targets in the headset; this module tells Capture, the way Pupil Labs' hmd-eyes does:

1. ``start_plugin`` ``HMD3DChoreographyPlugin`` (Capture >= 2.0; ``HMD_Calibration_3D`` before, chosen by Pupil
   Remote's ``v`` reply);
2. ``calibration.should_start`` with ``translation_eye0`` / ``translation_eye1``: the right / left eye's centre in
   mm (Pupil's eye 0 is the right eye); Capture answers ``calibration.started``;
3. per target, one ``calibration.add_ref_data`` whose ``ref_data`` holds ``{"mm_pos": [x, y, z], "timestamp": t}``
   per displayed frame: the target's position in mm and the frame's display time in Pupil time (the client's
   clock sync, :meth:`~psyop.devices.gaze.pupil.PupilClient.clock_sync`);
4. ``calibration.should_stop``; Capture matches pupil data to the reference points by time, fits its HMD 3-D
   gaze model and sends ``calibration.successful`` (then ``calibration.result.v2`` with the fitted
   ``params``) or ``calibration.failed`` with a ``reason`` (Capture >= 2.0: the error's class name, e.g.
   ``CalibrationError``; its log window says more).

Every notification goes through Pupil Remote (REQ, multipart ``notify.<subject>`` + msgpack map; reply
``Message forwarded.``), on a REQ socket of its own (the client's sync thread owns the client's); the answers are
read from the IPC backbone (SUB on ``SUB_PORT``, topic ``notify.``), each wait bounded by a deadline.

Frame: reference points are sent in Pupil's world-camera convention (x right, y down, z forward, mm:
:func:`~psyop.devices.gaze.pupil.head_m_to_world_mm`), so the gaze Capture maps afterwards, which is in the frame
of its reference points, decodes with :func:`~psyop.devices.gaze.pupil.world_mm_to_head_m` like every Pupil datum.
(hmd-eyes sends Unity camera coordinates, y up, and divides y by the camera's aspect ratio in
CalibrationController.AddSample; psyop sends the targets' true positions.)

Accuracy: Capture computes none for an HMD calibration (accuracy_visualizer.py: "Accuracy visualization is
disabled for HMD calibration"), so none is reported here; the protocol's gaze validation measures it.

Sources (read with the search tool): pupil-labs/pupil pupil_src/shared_modules/calibration_choreography/
hmd_plugin.py and base_plugin.py, gaze_mapping/gazer_base.py, gaze_mapping/notifications.py,
gaze_mapping/gazer_3d/gazer_hmd.py (``mm_pos``), accuracy_visualizer.py; pupil-labs/hmd-eyes
Runtime/Scripts/CalibrationController.cs and Calibration.cs; pupil-labs/pupil-helpers
python/hmd_calibration_client.py (the same over Pupil Remote, eye translations +-34.75 mm, depths 0.6/1/2 m).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import msgpack
import zmq

from psyop.devices.gaze.pupil import PupilClient, decode_message, head_m_to_world_mm
from psyop.session.headset_calibration import CalibrationResult, CalibrationUnavailable, Vec3
from psyop.session.rows import JsonObject

__all__ = ["PLUGIN_BEFORE_2", "PLUGIN_FROM_2", "PupilHmdCalibration", "plugin_for_version"]

PLUGIN_FROM_2 = "HMD3DChoreographyPlugin"
PLUGIN_BEFORE_2 = "HMD_Calibration_3D"
_RESULTS = ("calibration.successful", "calibration.failed")
_KEPT = frozenset({"start_plugin", "calibration.started", "calibration.stopped", "calibration.result.v2", *_RESULTS})
_FIX_FAILED = ("check in Capture's eye windows that both pupils are tracked (confidence near 1) while the participant "
               "looks at each target, and Capture's log for the cause")


def plugin_for_version(version: str) -> str:
    """The HMD 3-D calibration plugin's name for Capture's version string (``v``: e.g. '3.5.1')."""
    major = version.strip().lstrip("v").split(".")[0]
    return PLUGIN_BEFORE_2 if major.isdigit() and int(major) < 2 else PLUGIN_FROM_2


def _json_safe(value: object) -> object:
    """``value`` as JSON can hold it (map keys as strings, tuples as lists, anything else as text)."""
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if value is None or isinstance(value, (bool, int, str)):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else str(value)
    return str(value)


class PupilHmdCalibration:
    """Pupil Capture's HMD 3-D calibration for a started :class:`PupilClient` (see the module docstring).
    ``reply_timeout_s``: the longest wait for Pupil Remote's reply and for ``calibration.started``."""

    def __init__(self, client: PupilClient, *, reply_timeout_s: float = 5.0) -> None:
        self.client = client
        self.reply_timeout_s = reply_timeout_s
        self.version = ""
        self.plugin = ""
        self._ctx: zmq.Context | None = None
        self._req: zmq.Socket | None = None
        self._sub: zmq.Socket | None = None
        self._notes: list[JsonObject] = []  # the calibration notifications seen on the backbone this attempt
        self._n_sent = 0

    @property
    def tracker(self) -> str:
        return f"Pupil Capture {self.version or '?'} {self.plugin or 'HMD calibration'} at {self.client.address}"

    # HeadsetCalibration ------------------------------------------------------------------------------------
    def begin(self, eye_centres_m: tuple[Vec3, Vec3]) -> None:
        """Open the sockets, start the plugin and Capture's calibration (``calibration.started`` awaited)."""
        self.close()
        if self.client.sub_port is None:
            raise CalibrationUnavailable(f"the Pupil client at {self.client.address} is not started")
        self._notes, self._n_sent = [], 0
        self._ctx = zmq.Context()
        self._req = self._ctx.socket(zmq.REQ)
        self._req.setsockopt(zmq.LINGER, 0)
        self._req.setsockopt(zmq.REQ_RELAXED, 1)
        self._req.setsockopt(zmq.REQ_CORRELATE, 1)
        self._req.connect(self.client.address)
        self._sub = self._ctx.socket(zmq.SUB)
        self._sub.setsockopt(zmq.LINGER, 0)
        self._sub.connect(f"tcp://{self.client.host}:{self.client.sub_port}")
        self._sub.setsockopt_string(zmq.SUBSCRIBE, "notify.")
        self.version = self._ask("v")
        self.plugin = plugin_for_version(self.version)
        self._start_plugin()
        left_m, right_m = eye_centres_m
        started_at = len(self._notes)
        self._notify({"subject": "calibration.should_start", "translation_eye0": list(head_m_to_world_mm(right_m)),
                      "translation_eye1": list(head_m_to_world_mm(left_m)), "record": True})
        if self._wait_for(("calibration.started",), time.monotonic() + self.reply_timeout_s, started_at) is None:
            self.close()
            raise CalibrationUnavailable(
                f"{self.tracker} did not answer calibration.should_start with calibration.started within "
                f"{self.reply_timeout_s:g} s: is the {self.plugin} plugin available (Pupil Capture or Service >= 2.0 "
                "names it HMD3DChoreographyPlugin, older ones HMD_Calibration_3D) and no calibration already running?")

    def add_reference(self, position_m: Vec3, times_s: Sequence[float]) -> None:
        """One ``calibration.add_ref_data``: ``position_m`` in mm at each frame's Pupil time."""
        sync = self.client.clock_sync()
        if sync is None:
            raise CalibrationUnavailable(f"no clock sync with Pupil Capture at {self.client.address}")
        mm_pos = list(head_m_to_world_mm(position_m))
        ref_data = [{"mm_pos": mm_pos, "timestamp": sync.to_tracker(float(t))} for t in times_s]
        self._notify({"subject": "calibration.add_ref_data", "ref_data": ref_data, "record": True})
        self._n_sent += len(ref_data)
        self._receive(0.0)  # keep the backbone drained (an early calibration.failed is kept)

    def finish(self, timeout_s: float) -> CalibrationResult:
        """``calibration.should_stop``, then Capture's verdict (and ``calibration.result.v2``) within ``timeout_s``."""
        if self._req is None:
            return CalibrationResult("not_started", "the calibration was not started", self.tracker)
        try:
            stopped_at = len(self._notes)
            self._notify({"subject": "calibration.should_stop", "record": True})
            deadline_s = time.monotonic() + timeout_s
            verdict = self._wait_for(_RESULTS, deadline_s, stopped_at)
            if verdict is None:
                return CalibrationResult(
                    "timeout", f"no calibration.successful or calibration.failed within {timeout_s:g} s of "
                    "calibration.should_stop", self.tracker, fix="check that Pupil Capture is running and responsive",
                    details=self._details(None, None))
            result_note = None
            if verdict["subject"] == "calibration.successful":
                if self.plugin == PLUGIN_FROM_2:  # Capture >= 2.0 sends the fitted params right after (gazer_base.py)
                    result_note = self._wait_for(("calibration.result.v2",), min(deadline_s, time.monotonic()
                                                                                 + self.reply_timeout_s), stopped_at)
                return CalibrationResult("successful", "", self.tracker, details=self._details(verdict, result_note))
            return CalibrationResult("failed", f"Capture's reason: {verdict.get('reason', '')!s}", self.tracker,
                                     fix=_FIX_FAILED, details=self._details(verdict, None))
        except CalibrationUnavailable as exc:
            return CalibrationResult("not_started", str(exc), self.tracker)
        finally:
            self.close()

    def close(self) -> None:
        """Close this attempt's sockets (idempotent)."""
        for sock in (self._req, self._sub):
            if sock is not None:
                sock.close(0)
        self._req = self._sub = None
        if self._ctx is not None:
            self._ctx.term()
            self._ctx = None

    # Pupil Remote and the backbone ---------------------------------------------------------------------
    def _details(self, verdict: JsonObject | None, result_note: JsonObject | None) -> JsonObject:
        return {"capture_version": self.version, "plugin": self.plugin, "reference_points_sent": self._n_sent,
                "gazer": str(verdict.get("gazer_class_name", "")) if verdict is not None else None,
                "capture_result_params": _json_safe(result_note.get("params")) if result_note is not None else None}

    def _reply(self) -> str | None:
        assert self._req is not None
        deadline_s = time.monotonic() + self.reply_timeout_s
        while (left_s := deadline_s - time.monotonic()) > 0:
            if not self._req.poll(max(1, int(left_s * 1000))):
                return None
            try:
                return self._req.recv(zmq.NOBLOCK).decode("utf-8", errors="replace")
            except zmq.Again:
                continue
        return None

    def _ask(self, command: str) -> str:
        assert self._req is not None
        self._req.send_string(command)
        reply = self._reply()
        if reply is None:
            raise CalibrationUnavailable(f"Pupil Remote at {self.client.address} did not answer {command!r} within "
                                         f"{self.reply_timeout_s:g} s")
        return reply

    def _notify(self, note: JsonObject) -> None:
        """Send a notification through Pupil Remote; it must say 'Message forwarded.'."""
        assert self._req is not None
        topic = f"notify.{note['subject']}"
        self._req.send_multipart([topic.encode(), msgpack.packb({**note, "topic": topic}, use_bin_type=True)])
        reply = self._reply()
        if reply != "Message forwarded.":
            raise CalibrationUnavailable(f"Pupil Remote at {self.client.address} answered {topic} with "
                                         f"{str(reply)[:40]!r}, not 'Message forwarded.'")

    def _start_plugin(self) -> None:
        """``start_plugin`` until its own echo arrives on the backbone (so the subscription is live: a SUB socket
        misses what is published before it has joined)."""
        deadline_s = time.monotonic() + self.reply_timeout_s
        while time.monotonic() < deadline_s:
            sent_at = len(self._notes)
            self._notify({"subject": "start_plugin", "name": self.plugin, "args": {}})
            echo = self._wait_for(("start_plugin",), min(deadline_s, time.monotonic() + 0.25), sent_at)
            if echo is not None and echo.get("name") == self.plugin:
                return
        raise CalibrationUnavailable(f"no notification came back from Pupil Capture's backbone (SUB_PORT "
                                     f"{self.client.sub_port}) within {self.reply_timeout_s:g} s")

    def _receive(self, wait_s: float) -> None:
        """Keep the notifications that arrive within ``wait_s`` (all that are waiting when 0)."""
        assert self._sub is not None
        timeout_ms = max(0, int(wait_s * 1000))
        while self._sub.poll(timeout_ms):
            timeout_ms = 0
            parts = self._sub.recv_multipart()
            try:
                note = decode_message(parts[1])
            except (IndexError, ValueError, msgpack.UnpackException):
                continue
            if note.get("subject") in _KEPT:  # not the reference data's own echo, nor the pupil data of setup.v2
                self._notes.append(note)

    def _wait_for(self, subjects: tuple[str, ...], deadline_s: float, start: int) -> JsonObject | None:
        """The first notification with one of ``subjects`` from ``self._notes[start:]`` on, waiting until
        ``deadline_s`` (monotonic) at most; None when none came."""
        while True:
            for note in self._notes[start:]:
                if note.get("subject") in subjects:
                    return note
            left_s = deadline_s - time.monotonic()
            if left_s <= 0:
                return None
            self._receive(min(left_s, 0.05))
