"""What every photometer adapter shares: the reading, and a command/reply link over pyserial.

:class:`SerialLink` sends one command and reads one reply line within a deadline (pyserial reads with a short
timeout in a loop, never blocking forever). Each fault is a one-line :class:`~psyop.errors.UserError` naming the
device (``ls100 on /dev/ttyUSB0``) and the fix:

- no reply before the deadline (device off, wrong port, not in remote mode);
- the port fails while waiting or writing (``serial.SerialException`` / ``OSError``: a pulled cable, the device
  switched off; on a pty, the other end closed);
- a reply that is no ASCII text line (non-ASCII bytes, NUL, a line over ``MAX_REPLY_BYTES``): garbage, usually a
  wrong baud rate or framing, or another device on the port.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import serial

from psyop.errors import UserError

try:
    import termios

    #: what a failing port raises: pyserial's error, the OS's, and termios's (a flush on a hung-up tty)
    PORT_ERRORS: tuple[type[BaseException], ...] = (serial.SerialException, OSError, termios.error)
except ImportError:  # Windows: no termios
    PORT_ERRORS = (serial.SerialException, OSError)

MAX_REPLY_BYTES = 256


@dataclass(frozen=True)
class Reading:
    """One measurement: luminance (cd/m²), CIE 1931 x, y where the device gives them, the raw reply line."""

    luminance_cd_m2: float
    x: float | None = None
    y: float | None = None
    raw: str = ""
    quality: str | None = None  # the device's own flag on a kept reading (PR-650 "low light")


class SerialLink:
    """One serial port, spoken to in command/reply lines."""

    def __init__(self, label: str, port: str, *, settings: dict, fix: str) -> None:
        self.label, self.port, self.fix = label, port, fix
        try:
            self._serial = serial.serial_for_url(port, timeout=0.05, write_timeout=2.0, **settings)
            self._pending = bytearray()  # bytes read past the last reply line (a reply of several lines)
        except (serial.SerialException, ValueError, OSError) as exc:
            raise UserError(f"{label}: cannot open the port ({exc}); check the path and your permissions on it "
                            "(ls -l; the dialout group), then rerun") from None

    def garbage(self, raw: bytes | str, command: str) -> UserError:
        return UserError(f"{self.label}: answered garbage {raw!r} to {command}; {self.fix}")

    def send(self, data: bytes, command: str) -> None:
        try:
            self._serial.reset_input_buffer()  # a late reply to an earlier command is not this one's
            self._pending.clear()
            self._serial.write(data)
            self._serial.flush()
        except PORT_ERRORS as exc:
            raise self._lost(command, exc) from None

    def _lost(self, command: str, exc: BaseException) -> UserError:
        detail = exc.args[-1] if len(exc.args) == 2 else exc  # (errno, text) of OSError and termios.error
        return UserError(f"{self.label}: the connection failed during {command} ({detail}): the cable was pulled or "
                         "the device switched off; reconnect it and rerun")

    def read_line(self, command: str, timeout_s: float) -> str:
        """The next non-empty reply line (CR/LF stripped), within ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        buffer = self._pending
        while True:
            end = min((i for i in (buffer.find(b"\n"), buffer.find(b"\r")) if i >= 0), default=-1)
            if end >= 0:
                raw = bytes(buffer[:end])
                del buffer[: end + 1]
                if raw.strip(b" \t"):
                    return self._text(raw, command)
                continue
            if len(buffer) > MAX_REPLY_BYTES:
                raise self.garbage(bytes(buffer[:40]) + b"...", command)
            if time.monotonic() > deadline:
                if buffer:
                    raise self.garbage(bytes(buffer), command)
                raise UserError(f"{self.label}: no reply to {command} within {timeout_s:g} s; {self.fix}")
            try:
                buffer += self._serial.read(max(1, self._serial.in_waiting))
            except PORT_ERRORS as exc:
                raise self._lost(command, exc) from None

    def _text(self, raw: bytes, command: str) -> str:
        try:
            text = raw.decode("ascii")
        except UnicodeDecodeError:
            raise self.garbage(raw, command) from None
        if not text.isprintable():
            raise self.garbage(raw, command)
        return text.strip()

    def command(self, text: str, terminator: str, timeout_s: float) -> str:
        """Send ``text`` + ``terminator``; the reply line."""
        self.send((text + terminator).encode("ascii"), text)
        return self.read_line(text, timeout_s)

    def close(self) -> None:
        try:
            self._serial.close()
        except PORT_ERRORS:  # the port is gone already (a pulled cable)
            pass
