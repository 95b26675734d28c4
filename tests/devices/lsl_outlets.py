"""Real LSL outlets (pylsl) shaped like a tracker's, pushing a known gaze path for the tests.

:class:`PupilRelayOutlet` declares the stream exactly as Pupil Capture's LSL relay plugin does
(labstreaminglayer/App-PupilLabs ``pupil_capture_lsl_relay``): name ``pupil_capture``, type
``Gaze``, 22 ``cf_double64`` channels whose ``desc/channels/channel`` entries carry ``label``,
``eye``, ``type``, ``unit`` and ``coordinate_system``, in the relay's order. Each pushed sample is
remembered with its LSL timestamp, so a test can compare what psyop logged with what was sent.
"""

from __future__ import annotations

import math
import random
import threading
import time
import uuid

import pylsl

#: the relay's channels, in its order: (label, eye, type, unit)
PUPIL_RELAY_CHANNELS: tuple[tuple[str, str, str, str], ...] = (
    ("confidence", "both", "Confidence", "normalized"),
    ("norm_pos_x", "both", "ScreenX", "normalized"), ("norm_pos_y", "both", "ScreenY", "normalized"),
    *((f"gaze_point_3d_{a}", "both", f"Direction{a.upper()}", "mm") for a in "xyz"),
    *((f"eye_center{e}_3d_{a}", ("right", "left")[e], f"Position{a.upper()}", "mm") for e in range(2) for a in "xyz"),
    *((f"gaze_normal{e}_{a}", ("right", "left")[e], f"Position{a.upper()}", "mm") for e in range(2) for a in "xyz"),
    *((f"diameter{e}_2d", ("right", "left")[e], "Diameter", "pixels") for e in range(2)),
    *((f"diameter{e}_3d", ("right", "left")[e], "Diameter", "mm") for e in range(2)),
)


def pupil_relay_info(name: str = "pupil_capture", rate_hz: float = 200.0) -> pylsl.StreamInfo:
    """The relay's stream declaration (``rate_hz`` 0: an irregular-rate stream)."""
    info = pylsl.StreamInfo(name, "Gaze", len(PUPIL_RELAY_CHANNELS), rate_hz, pylsl.cf_double64, str(uuid.uuid4()))
    info.desc().append_child_value("pupil_lsl_relay_version", "2.1.0")
    channels = info.desc().append_child("channels")
    for label, eye, kind, unit in PUPIL_RELAY_CHANNELS:
        channel = channels.append_child("channel")
        channel.append_child_value("label", label)
        channel.append_child_value("eye", eye)
        channel.append_child_value("type", kind)
        channel.append_child_value("unit", unit)
        channel.append_child_value("coordinate_system", "world" if "diameter" not in label else f"eye{label[8]}")
    return info


def known_path(k: int) -> list[float]:
    """The relay sample number ``k``: a gaze point circling 10 deg around straight ahead at 0.8 m
    (world camera: x right, y down, z forward, mm), both eyes, pupils 3-4 mm; every 50th sample a
    blink (NaN gaze point, confidence 0)."""
    angle = 2.0 * math.pi * k / 400.0
    x, y, z = 800.0 * math.tan(math.radians(10.0)) * math.cos(angle), 800.0 * math.tan(math.radians(10.0)) * math.sin(angle), 800.0
    confidence = 0.0 if k % 50 == 49 else 0.9 + 0.05 * math.sin(k)
    point = [math.nan] * 3 if k % 50 == 49 else [x, y, z]
    eyes = [31.0, 2.0, -20.0, -31.0, 2.0, -20.0]
    normals = [0.02, 0.01, 0.9997, -0.02, 0.01, 0.9997]
    pupils = [40.0 + k % 7, 42.0 + k % 5, 3.0 + 0.001 * k, 3.5 + 0.001 * k]
    return [confidence, 0.5 + 0.1 * math.cos(angle), 0.5 + 0.1 * math.sin(angle), *point, *eyes, *normals, *pupils]


class PupilRelayOutlet:
    """Pushes :func:`known_path` at ``rate_hz`` from its own thread, each sample stamped with
    ``pylsl.local_clock()`` when pushed (as the relay stamps Pupil time synchronised to LSL).

    Faults on demand, each from the next sample the thread pushes: :meth:`step` shifts every
    later stamp (a clock that jumps; ``step_at`` is then the first shifted stamp), :meth:`gap`
    drops samples (missing from stamps and arrivals alike), :meth:`hold` withholds samples and
    then pushes them at once with their own stamps (a sender's backlog); ``jitter_s`` adds
    uniform noise of up to that much to each stamp."""

    def __init__(self, name: str = "pupil_capture", rate_hz: float = 200.0, jitter_s: float = 0.0,
                 irregular: bool = False) -> None:
        self.rate_hz = rate_hz
        self.jitter_s = jitter_s
        self.step_at: float | None = None
        self._random = random.Random(7)
        self._shift_s = 0.0
        self._pending_shift_s = 0.0
        self._to_skip = 0
        self._to_hold = 0
        self.info = pupil_relay_info(name, 0.0 if irregular else rate_hz)  # irregular: declared so, pushed at rate_hz
        self.outlet: pylsl.StreamOutlet | None = pylsl.StreamOutlet(self.info)
        self.pushed: list[tuple[int, float]] = []  # (k, timestamp)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._paused = threading.Event()
        self._thread = threading.Thread(target=self._push, daemon=True)
        self._thread.start()

    def _push(self) -> None:
        period = 1.0 / self.rate_hz
        k, next_t = 0, time.monotonic()
        held: list[tuple[int, float]] = []
        while not self._stop.is_set():
            next_t += period
            self._stop.wait(max(0.0, next_t - time.monotonic()))
            if self._paused.is_set() or self.outlet is None:
                continue
            with self._lock:
                stepped = self._pending_shift_s != 0.0
                self._shift_s += self._pending_shift_s
                self._pending_shift_s = 0.0
                stamp = pylsl.local_clock() + self._shift_s + self._random.uniform(-self.jitter_s, self.jitter_s)
                if stepped:
                    self.step_at = stamp
                skip = self._to_skip > 0
                self._to_skip -= skip
                hold = not skip and self._to_hold > 0
                self._to_hold -= hold
            if not skip:
                held.append((k, stamp))
            k += 1
            if hold or not held:
                continue
            for k_held, stamp_held in held:
                self.outlet.push_sample(known_path(k_held), stamp_held)
            with self._lock:
                self.pushed.extend(held)
            held = []

    def step(self, by_s: float) -> None:
        """Shift every stamp from the next sample on by ``by_s`` (negative: back)."""
        with self._lock:
            self._pending_shift_s += by_s

    def gap(self, n: int) -> None:
        """Drop the next ``n`` samples (never sent)."""
        with self._lock:
            self._to_skip += n

    def hold(self, n: int) -> None:
        """Withhold the next ``n`` samples, then push them at once with the one after them."""
        with self._lock:
            self._to_hold += n

    def faults_done(self) -> bool:
        """Every requested step, gap and hold has been pushed through."""
        with self._lock:
            return self._to_skip == 0 and self._to_hold == 0 and self._pending_shift_s == 0.0

    def sent(self) -> list[tuple[int, float]]:
        with self._lock:
            return list(self.pushed)

    def close(self) -> None:
        """Stop pushing and destroy the outlet (its inlets see the stream lost)."""
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.outlet = None
