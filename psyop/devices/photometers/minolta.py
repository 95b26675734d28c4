"""Konica Minolta LS-100 / LS-110 luminance meters over RS-232 (``--photometer ls100:PORT``, ``ls110:PORT``).

The protocol, from the LS-100/LS-110 instruction manual's "Communication" section (data communication with a
computer) as PsychoPy's driver speaks it (psychopy/hardware/minolta.py, class ``LS100``):

- the meter is in communication mode when switched on with the F key held (``[`` at the display's bottom right);
- 4800 baud, 7 data bits, even parity, 2 stop bits; commands end with CR LF, replies too;
- ``MDS,04`` sets the absolute measuring mode; the reply is ``OK00``;
- ``MES`` measures; the reply is ``OKnn,<luminance>``, the luminance in cd/m² (e.g. ``OK00,  123.4`` or
  ``OK11,+1.234E+02``: PsychoPy takes the last whitespace-separated field; this parser takes the number after the
  first comma, sign, spaces and exponent allowed);
- an error reply is ``ERnn``: ER00 unknown command, ER01 setting error, ER10 measuring range over, ER11 memory
  value error, ER19 display range over, ER20 EEPROM error (the meter needs repair), ER30 battery exhausted
  (PsychoPy's ``codes`` table).

The LS-100 reports no serial number over the line (``serial_number`` null) and no chromaticity.
"""

from __future__ import annotations

import re

import serial

from psyop.devices.photometers.base import Reading, SerialLink
from psyop.errors import UserError

ERRORS = {
    "00": ("unknown command", "the meter is not in communication mode: switch it off, hold F while switching it on "
                              "('[' at the display's bottom right), then rerun"),
    "01": ("setting error", "switch the meter off and on with F held, then rerun"),
    "10": ("measuring range over", "the patch is brighter than the meter's range: lower the display's brightness "
                                   "or fit the ND filter, then rerun"),
    "11": ("memory value error", "switch the meter off and on with F held, then rerun"),
    "19": ("display range over", "the patch is brighter than the meter's display range: lower the display's "
                                 "brightness, then rerun"),
    "20": ("EEPROM error", "the meter needs repair (Konica Minolta service)"),
    "30": ("battery exhausted", "replace the meter's battery, then rerun"),
}
_MEASURED = re.compile(r"^OK(\d\d),\s*([+-]?\s*(?:\d+\.?\d*|\.\d+)(?:[Ee][+-]?\d+)?)\s*$")
FIX = ("check the cable and the port, and that the meter is in communication mode (switch it on with F held: '[' "
       "shows); the line must be 4800 baud 7E2")


class MinoltaLS100:
    """An LS-100 or LS-110 on ``port``."""

    interactive = False

    def __init__(self, port: str, *, kind: str = "ls100", timeout_s: float = 5.0) -> None:
        self.kind, self.port, self.timeout_s = kind, port, timeout_s
        self.label = f"{kind} on {port}"
        self.link = SerialLink(self.label, port, fix=FIX, settings={
            "baudrate": 4800, "bytesize": serial.SEVENBITS, "parity": serial.PARITY_EVEN,
            "stopbits": serial.STOPBITS_TWO})
        try:
            self._command("MDS,04")  # absolute measuring mode
        except UserError:
            self.link.close()
            raise

    def _command(self, command: str) -> str:
        reply = self.link.command(command, "\r\n", self.timeout_s)
        if reply.startswith("ER"):
            meaning, fix = ERRORS.get(reply[2:4], ("an undocumented error", "switch the meter off and on with F "
                                                   "held, then rerun"))
            raise UserError(f"{self.label}: answered {reply} ({meaning}) to {command}; {fix}")
        if not reply.startswith("OK"):
            raise self.link.garbage(reply, command)
        return reply

    def measure(self) -> Reading:
        reply = self._command("MES")
        match = _MEASURED.match(reply)
        if match is None:
            raise self.link.garbage(reply, "MES")
        return Reading(float(match.group(2).replace(" ", "")), raw=reply)

    def describe(self) -> dict:
        return {"kind": self.kind, "model": "Konica Minolta LS-100/LS-110", "port": self.port,
                "serial_number": None, "settings": "4800 baud 7E2, CR LF", "mode": "MDS,04 (absolute)"}

    def close(self) -> None:
        self.link.close()
