"""Photo Research SpectraScan spectroradiometers: PR-650 (``--photometer pr650:PORT``) and PR-655 / PR-670
(``pr655:PORT``, ``pr670:PORT``), in remote mode over their serial (RS-232 or USB virtual serial) line.

PR-650, after the PR-650 manual's "Remote mode" commands as PsychoPy speaks them (psychopy/hardware/pr.py,
class ``PR650``):

- 9600 baud, 8 data bits, no parity, 1 stop bit; a command ends with CR (PsychoPy sends LF; the meter takes
  either); the first command must come within seconds of switching the meter on;
- ``B1`` (backlight on) opens remote mode; the reply is ``000`` (PsychoPy's ``codes['OK']``);
- ``S01,,,,,,01,1`` sets up the measurement: MS-75 primary lens, adaptive integration, metric units (the last
  field, 1: cd/m²), as PsychoPy sends it; the reply is a numeric status, 0 when accepted;
- ``M1`` measures and returns data code 1 (PsychoPy measures with ``M0`` and downloads with ``D2``; ``M1`` is
  the same measurement with its luminance and chromaticity in one reply): ``qq,U,Y.YYYe+ee,x.xxxx,y.yyyy`` with
  qq the quality code (00 OK; 10 and 18 "light low", PsychoPy's ``codes``: the reading is kept and flagged),
  U the units (1 metric: cd/m²; 0 English: footlamberts, converted), Y the luminance, x, y CIE 1931;
  any other quality code is an error.

PR-655 / PR-670, after the PR-655/670 remote-mode command set (PsychoPy's class ``PR655``; the "M Command" and
data-code descriptions quoted in the PR-6XX MATLAB toolboxes):

- ``PHOTO`` (no terminator) enters remote mode (the meter answers ``REMOTE MODE``); ``Q`` leaves it;
- commands end with CR; each reply is ``qqqqq,<data>`` with qqqqq the error code (00000 OK);
- ``D111``: the model (``00000,PR-655``); ``D110``: the serial number (``00000,67065106``);
- ``SU1``: metric units; ``M1``: measure, data code 1: ``qqqqq,UUUU,Y.YYYe+ee,x.xxxx,y.yyyy``;
- a non-zero qqqqq is an error (the manual's error code table names it).
"""

from __future__ import annotations

import re

import serial

from psyop.devices.photometers.base import Reading, SerialLink
from psyop.errors import UserError

FOOTLAMBERT_CD_M2 = 3.4262591  # 1 fL = 1/pi cd/ft^2
SETTINGS = {"baudrate": 9600, "bytesize": serial.EIGHTBITS, "parity": serial.PARITY_NONE,
            "stopbits": serial.STOPBITS_ONE}
LIGHT_LOW_650 = {"10", "18"}
_NUMBER = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[Ee][+-]?\d+)?"
_DATA_1 = re.compile(rf"^(\d+),(\d+),({_NUMBER}),({_NUMBER}),({_NUMBER})$")
FIX_650 = ("check the cable and the port (9600 8N1), and that the PR-650 was switched on just before the run "
           "(remote mode opens only in its first seconds)")
FIX_655 = "check the USB cable and the port, and that the meter is switched on and idle (not in a menu)"


def parse_data_code_1(reply: str, label: str, command: str, *, light_low: set[str]) -> Reading:
    """A data code 1 reply ``quality,units,Y,x,y`` (a UserError for an error code or garbage)."""
    fields = reply.split(",")
    if fields and fields[0].strip().isdigit() and int(fields[0]) != 0 and fields[0].strip() not in light_low:
        raise UserError(f"{label}: answered error code {fields[0].strip()} to {command} ({reply!r}); look the code "
                        "up in the meter's manual (remote mode error codes), fix the cause (aim, focus, light level) "
                        "and rerun")
    match = _DATA_1.match(reply.replace(" ", ""))
    if match is None:
        raise UserError(f"{label}: answered garbage {reply!r} to {command}; check the line settings (9600 8N1) "
                        "and that the meter is in remote mode, then rerun")
    quality, units, y_value, x, y = match.groups()
    luminance = float(y_value) * (FOOTLAMBERT_CD_M2 if int(units) == 0 else 1.0)
    flag = f"light low (code {quality})" if int(quality) != 0 else None
    return Reading(luminance, float(x), float(y), raw=reply, quality=flag)


def _status(reply: str, label: str, command: str) -> str:
    """The data after a numeric status that must be 0 (``000``, ``00000,PR-655``)."""
    head, _, data = reply.partition(",")
    if not head.strip().isdigit():
        raise UserError(f"{label}: answered garbage {reply!r} to {command}; check the port and the line settings "
                        "(9600 8N1), then rerun")
    if int(head) != 0:
        raise UserError(f"{label}: answered error code {head.strip()} to {command}; look it up in the meter's "
                        "manual (remote mode error codes), fix the cause and rerun")
    return data.strip()


class PR650:
    """A PR-650 on ``port``."""

    interactive = False
    kind = "pr650"

    def __init__(self, port: str, *, timeout_s: float = 30.0) -> None:
        self.port, self.timeout_s = port, timeout_s
        self.label = f"pr650 on {port}"
        self.link = SerialLink(self.label, port, settings=SETTINGS, fix=FIX_650)
        try:
            _status(self.link.command("B1", "\r", min(timeout_s, 5.0)), self.label, "B1")
            _status(self.link.command("S01,,,,,,01,1", "\r", min(timeout_s, 5.0)), self.label, "S01,,,,,,01,1")
        except UserError:
            self.link.close()
            raise

    def measure(self) -> Reading:
        reply = self.link.command("M1", "\r", self.timeout_s)
        return parse_data_code_1(reply, self.label, "M1", light_low=LIGHT_LOW_650)

    def describe(self) -> dict:
        return {"kind": self.kind, "model": "Photo Research PR-650", "port": self.port, "serial_number": None,
                "settings": "9600 baud 8N1, CR", "setup": "S01,,,,,,01,1 (MS-75, adaptive, metric)"}

    def close(self) -> None:
        self.link.close()


class PR655:
    """A PR-655 or PR-670 on ``port``."""

    interactive = False

    def __init__(self, port: str, *, kind: str = "pr655", timeout_s: float = 30.0) -> None:
        self.kind, self.port, self.timeout_s = kind, port, timeout_s
        self.label = f"{kind} on {port}"
        self.link = SerialLink(self.label, port, settings=SETTINGS, fix=FIX_655)
        try:
            self.link.send(b"PHOTO", "PHOTO")
            self.link.read_line("PHOTO", min(timeout_s, 5.0))  # "REMOTE MODE"
            quick = min(timeout_s, 5.0)
            self.model = _status(self.link.command("D111", "\r", quick), self.label, "D111")
            self.serial_number = _status(self.link.command("D110", "\r", quick), self.label, "D110") or None
            _status(self.link.command("SU1", "\r", quick), self.label, "SU1")
        except UserError:
            self.close()
            raise

    def measure(self) -> Reading:
        reply = self.link.command("M1", "\r", self.timeout_s)
        return parse_data_code_1(reply, self.label, "M1", light_low=set())

    def describe(self) -> dict:
        return {"kind": self.kind, "model": "Photo Research PR-655/PR-670", "model_reported": self.model,
                "port": self.port, "serial_number": self.serial_number, "settings": "9600 baud 8N1, CR",
                "setup": "SU1 (metric)"}

    def close(self) -> None:
        try:
            self.link.send(b"Q", "Q")  # leave remote mode
        except UserError:
            pass
        self.link.close()
