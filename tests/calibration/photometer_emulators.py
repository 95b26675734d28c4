"""Photometers emulated on a real pty pair, speaking each vendor's documented command set and reply formats
(psyop/devices/photometers/ cites the sources), in front of a display with a known transfer function.

The emulator reads the patch log ``psyop calibrate --patch-log`` writes (one flushed JSON line per patch, written
before the photometer is asked) to know what is on screen, and answers from :class:`DisplayModel`. A ``fault``
starts after ``fault_after`` measurements: ``timeout`` (stops answering), ``error`` (the device's error reply),
``garbage`` (bytes that are no reply), ``pulled`` (the pty's device end closes: a pulled cable).
"""

from __future__ import annotations

import json
import os
import select
import sys
import threading
import tty
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "session"))
from session_helpers import wait_until  # noqa: F401  (the deadline poll the tests share)

SRGB_PRIMARIES = {"red": (0.64, 0.33), "green": (0.30, 0.60), "blue": (0.15, 0.06)}
D65 = (0.3127, 0.3290)
GARBAGE = b"\xff\xfe\x00\x81\x9cgarbage\xc3\r\n"


def power_law(v: np.ndarray) -> np.ndarray:
    return np.asarray(v, dtype=np.float64) ** 2.4


@dataclass
class DisplayModel:
    """A display: black level + (peak - black) * sum of channel weight * transfer(code / 255), cd/m²."""

    black_cd_m2: float = 0.3
    peak_cd_m2: float = 100.0
    weights: tuple[float, float, float] = (0.2126, 0.7152, 0.0722)
    transfer: Callable[[np.ndarray], np.ndarray] = field(default=power_law)
    noise_relative: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        self._rng = np.random.default_rng(self.seed)

    def channel_luminance(self, rgb: list[int]) -> np.ndarray:
        v = np.asarray(rgb, dtype=np.float64) / 255.0
        return (self.peak_cd_m2 - self.black_cd_m2) * np.asarray(self.weights) * self.transfer(v)

    def luminance(self, rgb: list[int]) -> float:
        """The true luminance of a patch (no noise)."""
        return float(self.black_cd_m2 + self.channel_luminance(rgb).sum())

    def measured(self, rgb: list[int]) -> float:
        value = self.luminance(rgb)
        if self.noise_relative:
            value *= 1.0 + self.noise_relative * float(self._rng.standard_normal())
        return value

    def chromaticity(self, rgb: list[int]) -> tuple[float, float]:
        """CIE 1931 x, y of the patch: the channels' XYZ (sRGB primaries) plus the black's (D65)."""
        parts = [(D65, self.black_cd_m2)] + list(zip(SRGB_PRIMARIES.values(), self.channel_luminance(rgb), strict=True))
        xyz = np.zeros(3)
        for (x, y), big_y in parts:
            xyz += np.array([x / y * big_y, big_y, (1 - x - y) / y * big_y])
        return float(xyz[0] / xyz.sum()), float(xyz[1] / xyz.sum())


class PtyPhotometer:
    """The device end of a pty; ``answer(command)`` is the device's protocol (subclasses)."""

    terminators = (b"\r", b"\n")

    def __init__(self, patch_log: Path, display: DisplayModel | None = None, *, fault: str | None = None,
                 fault_after: int = 0) -> None:
        self.patch_log, self.display = Path(patch_log), display or DisplayModel()
        self.fault, self.fault_after = fault, fault_after
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)
        self.commands: list[str] = []
        self.measurements = 0
        self.closed = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def screen(self) -> list[int]:
        """The patch on screen: the patch log's last line."""
        lines = self.patch_log.read_text().splitlines()
        return json.loads(lines[-1])["rgb"]

    def faulty(self) -> bool:
        """Count a measurement; whether the fault is due now."""
        self.measurements += 1
        return self.fault is not None and self.measurements > self.fault_after

    def fault_reply(self, error: bytes) -> bytes | None:
        if self.fault == "timeout":
            return None
        if self.fault == "garbage":
            return GARBAGE
        if self.fault == "pulled":
            self._close_master()
            return None
        return error

    def answer(self, command: str) -> bytes | None:
        raise NotImplementedError

    def _split(self, buffer: bytearray) -> list[str]:
        commands = []
        while True:
            if buffer.startswith(b"PHOTO"):  # PR-655/670: remote mode, no terminator
                del buffer[:5]
                commands.append("PHOTO")
                continue
            if buffer[:1] == b"Q" and len(buffer) == 1:  # PR-655/670: leave remote mode, no terminator
                buffer.clear()
                continue
            ends = [i for i in (buffer.find(b"\r"), buffer.find(b"\n")) if i >= 0]
            if not ends:
                return commands
            end = min(ends)
            text = bytes(buffer[:end]).decode("ascii", "replace").strip()
            del buffer[: end + 1]
            if text:
                commands.append(text)

    def _run(self) -> None:
        buffer = bytearray()
        while not self._stop.is_set() and not self.closed.is_set():
            readable, _, _ = select.select([self.master], [], [], 0.05)
            if not readable:
                continue
            try:
                chunk = os.read(self.master, 1024)
            except OSError:
                return
            buffer += chunk
            for command in self._split(buffer):
                self.commands.append(command)
                reply = self.answer(command)
                if self.closed.is_set():
                    return
                if reply is not None:
                    os.write(self.master, reply)

    def _close_master(self) -> None:
        if not self.closed.is_set():
            self.closed.set()
            os.close(self.master)

    def close(self) -> None:
        self._stop.set()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout=5.0)
        self._close_master()
        os.close(self.slave)


class LS100Emulator(PtyPhotometer):
    """Konica Minolta LS-100: ``MDS,04`` -> ``OK00``; ``MES`` -> ``OK00,+123.4``; errors ``ERnn``; CR LF."""

    error_reply = b"ER10\r\n"  # measuring range over

    def answer(self, command: str) -> bytes | None:
        if command.startswith("MDS"):
            return b"OK00\r\n"
        if command == "MES":
            rgb = self.screen()
            if self.faulty():
                return self.fault_reply(self.error_reply)
            return f"OK00,{self.display.measured(rgb):+#.4g}\r\n".encode()
        return b"ER00\r\n"


class PR650Emulator(PtyPhotometer):
    """PR-650: ``B1`` -> ``000``; ``S...`` -> ``000``; ``M1`` -> ``qq,U,Y,x,y`` (quality 18 below 1 cd/m²)."""

    error_reply = b"09\r\n"

    def answer(self, command: str) -> bytes | None:
        if command in ("B1", "b1") or command.upper().startswith("S"):
            return b"000\r\n"
        if command.upper() == "M1":
            rgb = self.screen()
            if self.faulty():
                return self.fault_reply(self.error_reply)
            value = self.display.measured(rgb)
            x, y = self.display.chromaticity(rgb)
            quality = "18" if value < 1.0 else "00"
            return f"{quality},1,{value:.3e},{x:.4f},{y:.4f}\r\n".encode()
        return b"01\r\n"


class PR655Emulator(PtyPhotometer):
    """PR-655: ``PHOTO`` -> `` REMOTE MODE``; ``D111`` -> model; ``D110`` -> serial; ``SU1``; ``M1``."""

    serial_number = "65104321"
    error_reply = b"00010\r\n"

    def answer(self, command: str) -> bytes | None:
        if command == "PHOTO":
            return b" REMOTE MODE\r\n"
        if command == "D111":
            return b"00000,PR-655\r\n"
        if command == "D110":
            return f"00000,{self.serial_number}\r\n".encode()
        if command == "SU1":
            return b"00000\r\n"
        if command == "M1":
            rgb = self.screen()
            if self.faulty():
                return self.fault_reply(self.error_reply)
            x, y = self.display.chromaticity(rgb)
            return f"00000,1,{self.display.measured(rgb):.3e},{x:.4f},{y:.4f}\r\n".encode()
        return b"-1\r\n"


def minolta_int(value: float) -> int:
    """A matrix entry in the ColorCAL's integer form (PsychoPy's _minolta2float, inverted)."""
    return round(value * 10000) if value >= 0 else 50000 + round(-value * 10000)


class ColorCalEmulator(PtyPhotometer):
    """CRS ColorCAL MKII: ``IDR``; ``r01``..``r03`` (the matrix, Minolta integers); ``MES`` -> raw X,Y,Z; LF CR, ``>``."""

    serial_number = "CC2-01234"
    error_reply = b"ER11\n\r>"
    matrix = np.array([[1.0631, -0.0347, 0.0120], [0.0210, 0.9874, -0.0115], [-0.0062, 0.0150, 1.0423]])

    def answer(self, command: str) -> bytes | None:
        if command == "IDR":
            return f"OK00,1,2.05,0,{self.serial_number},1,1201\n\r>".encode()
        if command in ("r01", "r02", "r03"):
            row = self.matrix[int(command[2]) - 1]
            return ("OK00," + ",".join(str(minolta_int(v)) for v in row) + "\n\r>").encode()
        if command == "MES":
            rgb = self.screen()
            if self.faulty():
                return self.fault_reply(self.error_reply)
            luminance = self.display.measured(rgb)
            x, y = self.display.chromaticity(rgb)
            xyz = np.array([x / y * luminance, luminance, (1 - x - y) / y * luminance])
            raw = np.linalg.solve(self.matrix, xyz)
            return ("OK00," + ",".join(f"{v:.5f}" for v in raw) + "\n\r>").encode()
        return b"ER00\n\r>"
