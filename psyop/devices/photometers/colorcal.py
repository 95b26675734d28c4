"""Cambridge Research Systems ColorCAL MKII colorimeter over its USB virtual serial port
(``--photometer colorcal:PORT``, e.g. ``colorcal:/dev/ttyACM0``).

The protocol as PsychoPy's driver speaks it (psychopy/hardware/crs/colorcal.py, class ``ColorCAL``, written with
CRS's support):

- a USB CDC line (any baud rate; PsychoPy opens it at 115200); commands end with LF; each reply line ends with
  LF CR and the reply ends with the prompt ``>``;
- ``IDR``: the device's identity, ``OK00,<f1>,<firmware>,<f3>,<serial number>,...,<firmware build>`` (PsychoPy
  takes the firmware from field 2, the serial number from field 4, the build from the last field);
- ``r01``, ``r02``, ``r03``: the rows of the calibration matrix, ``OK00,<a>,<b>,<c>``, each entry in Minolta's
  integer form (a positive value times 10000; a negative value as 50000 plus its magnitude times 10000:
  PsychoPy's ``_minolta2float``);
- ``MES``: measure, ``OK00,<X>,<Y>,<Z>`` raw tristimulus values; the calibration matrix times them gives CIE
  XYZ, Y the luminance in cd/m²;
- an error reply is ``ERnn`` (``ER11`` after ``UZC``: the sensor was not covered).

Devices with firmware build before 877 keep their zero calibration in volatile memory and need ``UZC`` (a zero
calibration, sensor covered) after each connection (PsychoPy's ``getNeedsCalibrateZero``); psyop does not run
it: such a device is refused with that fix.
"""

from __future__ import annotations

import serial

from psyop.devices.photometers.base import Reading, SerialLink
from psyop.errors import UserError

FIX = "check the USB cable and the port (a ColorCAL MKII shows as /dev/ttyACM*), then rerun"


def minolta_to_float(value: int) -> float:
    """A calibration matrix entry in Minolta's integer form as a float.

    Examples
    --------
    >>> minolta_to_float(10630), minolta_to_float(50347)
    (1.063, -0.0347)
    """
    return value / 10000.0 if value < 50000 else -(value - 50000) / 10000.0


class ColorCal:
    """A ColorCAL MKII on ``port``."""

    interactive = False
    kind = "colorcal"

    def __init__(self, port: str, *, timeout_s: float = 5.0) -> None:
        self.port, self.timeout_s = port, timeout_s
        self.label = f"colorcal on {port}"
        self.link = SerialLink(self.label, port, fix=FIX, settings={
            "baudrate": 115200, "bytesize": serial.EIGHTBITS, "parity": serial.PARITY_NONE,
            "stopbits": serial.STOPBITS_ONE})
        try:
            identity = self._command("IDR")
            self.firmware, self.serial_number = identity[2].strip(), identity[4].strip() or None
            self.build = identity[-1].strip()
            if self.build.isdigit() and int(self.build) < 877:
                raise UserError(f"{self.label}: firmware build {self.build} needs a zero calibration after each "
                                "connection, which psyop does not run; run it (PsychoPy's ColorCAL.calibrateZero, "
                                "sensor covered) or update the firmware, then rerun")
            self.matrix = [[minolta_to_float(int(v)) for v in self._command(f"r0{row}")[1:4]] for row in (1, 2, 3)]
        except (IndexError, ValueError):
            self.link.close()
            raise self.link.garbage("IDR / r01..r03 reply", "IDR") from None
        except UserError:
            self.link.close()
            raise

    def _command(self, command: str) -> list[str]:
        self.link.send((command + "\n").encode("ascii"), command)
        reply = self.link.read_line(command, self.timeout_s)
        while reply == ">":  # the prompt of an earlier reply
            reply = self.link.read_line(command, self.timeout_s)
        fields = reply.split(",")
        if fields[0].startswith("ER"):
            raise UserError(f"{self.label}: answered {fields[0]} to {command}; unplug the ColorCAL, plug it in "
                            "again, then rerun")
        if fields[0] != "OK00" or len(fields) < 2:
            raise self.link.garbage(reply, command)
        return fields

    def measure(self) -> Reading:
        fields = self._command("MES")
        try:
            raw = [float(v) for v in fields[1:4]]
        except ValueError:
            raise self.link.garbage(",".join(fields), "MES") from None
        if len(raw) != 3:
            raise self.link.garbage(",".join(fields), "MES")
        big_x, big_y, big_z = (sum(m * r for m, r in zip(row, raw, strict=True)) for row in self.matrix)
        total = big_x + big_y + big_z
        x, y = (big_x / total, big_y / total) if total > 0 else (None, None)
        return Reading(big_y, x, y, raw=",".join(fields))

    def describe(self) -> dict:
        return {"kind": self.kind, "model": "CRS ColorCAL MKII", "port": self.port,
                "serial_number": self.serial_number, "firmware": f"{self.firmware} build {self.build}",
                "settings": "USB CDC, LF", "calibration_matrix": self.matrix}

    def close(self) -> None:
        self.link.close()
