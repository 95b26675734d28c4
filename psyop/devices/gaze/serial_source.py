"""Gaze from a serial device streaming one text line per sample.

Line format: ``G <x_m> <y_m> <z_m> <confidence>`` (head space, metres), newline
terminated, optionally comma separated. The sample time is the line's arrival on the
session clock minus the device's stated ``latency_s``. Malformed lines and garbage
bytes are counted and skipped.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable

from psyop.session.gaze.plan import FixationPlan
from psyop.session.gaze.sample import GazeSample, RawBuffer, RawGazeSample, TrackerLost, is_usable
from psyop.session.gaze.sync import ClockSync
from psyop.devices.serial_lines import SerialLineReader

_SPLIT = re.compile(r"[,\s]+")


def parse_gaze_line(text: str) -> tuple[tuple[float, float, float], float] | None:
    """(fixation_m, confidence) from one line, or None when it is not a gaze line."""
    fields = _SPLIT.split(text.strip())
    if len(fields) != 5 or fields[0] != "G":
        return None
    try:
        x, y, z, confidence = (float(v) for v in fields[1:])
    except ValueError:
        return None
    if not math.isfinite(confidence):
        return None
    return (x, y, z), confidence


class SerialGazeSource:
    """:class:`~psyop.session.gaze.sample.GazeSource` over pyserial (any URL it accepts)."""

    def __init__(self, url: str, *, clock: Callable[[], float], latency_s: float = 0.0,
                 confidence_threshold: float = 0.6, lost_after_s: float = 1.0, baudrate: int = 115200) -> None:
        self._clock = clock
        self.latency_s = latency_s
        self.confidence_threshold = confidence_threshold
        self.lost_after_s = lost_after_s
        self._latest: GazeSample | None = None
        self._last_arrival_s = math.nan
        self._raw = RawBuffer()
        self._reader = SerialLineReader(url, self._on_line, clock, baudrate=baudrate)

    def _on_line(self, text: str, arrival_s: float) -> bool:
        parsed = parse_gaze_line(text)
        if parsed is None:
            return False
        fixation, confidence = parsed
        sample = GazeSample(arrival_s - self.latency_s, fixation, confidence,
                            is_usable(fixation, confidence, self.confidence_threshold))
        with self._reader.lock:
            self._latest = sample
            self._last_arrival_s = arrival_s
        self._raw.add(RawGazeSample.of(sample, tracker_t_s=math.nan, received_s=arrival_s))
        return True

    def start(self) -> None:
        self._reader.start()
        self._last_arrival_s = self._clock()

    def latest(self, now_s: float) -> GazeSample | None:
        with self._reader.lock:
            sample, last, error = self._latest, self._last_arrival_s, self._reader.error
        if error:
            raise TrackerLost(error)
        if self._clock() - last > self.lost_after_s:
            raise TrackerLost(f"no gaze line from {self._reader.url} for more than {self.lost_after_s} s")
        return sample

    def stats(self) -> dict[str, float | int]:
        with self._reader.lock:
            return {"lines": self._reader.lines, "garbage": self._reader.garbage}

    def set_plan(self, plan: FixationPlan) -> None:
        """No-op: a real tracker measures where the eye looks."""
        return None

    def clock_sync(self) -> ClockSync | None:
        """None: the line protocol carries no timestamp; samples are timed by their arrival."""
        return None

    def drain_raw(self) -> list[RawGazeSample]:
        """Every gaze line received since the last call (tracker time NaN: the lines carry none)."""
        return self._raw.drain()

    def close(self) -> None:
        self._reader.close()
