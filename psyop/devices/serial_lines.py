"""A garbage-tolerant line reader over pyserial, shared by the serial gaze source and
the serial response box.

The reader thread reads with a timeout (never blocks forever), so ``close`` always
joins it. Bytes that are not ASCII, lines that do not parse and over-long lines are
counted and skipped, never fatal. A line longer than ``MAX_LINE_BYTES`` is discarded whole,
up to and including its newline: its tail is never parsed as a line of its own.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import serial

MAX_LINE_BYTES = 256


class SerialLineReader:
    """Calls ``on_line(text, arrival_s)`` for every complete ASCII line on ``url``."""

    def __init__(self, url: str, on_line: Callable[[str, float], bool], clock: Callable[[], float], *, baudrate: int = 115200) -> None:
        self.url = url
        self._on_line = on_line
        self._clock = clock
        self._baudrate = baudrate
        self._port: serial.SerialBase | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.lock = threading.Lock()
        self.lines = 0
        self.garbage = 0
        self.error: str | None = None

    def start(self) -> None:
        try:
            self._port = serial.serial_for_url(self.url, baudrate=self._baudrate, timeout=0.05)
        except (serial.SerialException, ValueError, OSError) as exc:
            raise ConnectionError(f"cannot open serial device {self.url}: {exc}") from exc
        self._thread = threading.Thread(target=self._run, name=f"serial-{self.url}", daemon=True)
        self._thread.start()

    def write(self, data: bytes) -> None:
        assert self._port is not None
        self._port.write(data)

    def _run(self) -> None:
        assert self._port is not None
        buffer = bytearray()
        discarding = False  # inside an over-long line: drop everything up to its newline
        while not self._stop.is_set():
            try:
                chunk = self._port.read(max(1, self._port.in_waiting))
            except (serial.SerialException, OSError) as exc:
                with self.lock:
                    self.error = f"serial device {self.url} failed: {exc}"
                return
            if not chunk:
                continue
            buffer += chunk
            while True:
                end = buffer.find(b"\n")
                if end < 0:
                    if len(buffer) > MAX_LINE_BYTES:
                        buffer.clear()
                        if not discarding:
                            with self.lock:
                                self.garbage += 1
                        discarding = True
                    break
                if discarding or end > MAX_LINE_BYTES:  # the whole over-long line goes, not just its head
                    del buffer[: end + 1]
                    if not discarding:
                        with self.lock:
                            self.garbage += 1
                    discarding = False
                    continue
                raw = bytes(buffer[:end]).strip(b"\r \t\x00")
                del buffer[: end + 1]
                if not raw:
                    continue
                now = self._clock()
                try:
                    text = raw.decode("ascii")
                    accepted = self._on_line(text, now)
                except UnicodeDecodeError:
                    accepted = False
                with self.lock:
                    if accepted:
                        self.lines += 1
                    else:
                        self.garbage += 1

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self._port is not None:
            self._port.close()
