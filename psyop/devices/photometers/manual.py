"""Readings a person types (``--photometer manual``): one line per patch on stdin.

Each line is the luminance in cd/m², optionally followed by CIE 1931 x and y (spaces or commas between them):
``12.3`` or ``12.3 0.31 0.33``. A line that is not that is asked again (``MAX_TRIES`` times in a row); the end of
stdin before the last patch stops the run (the readings so far are kept, as for any fault).
"""

from __future__ import annotations

import math
import re
from typing import TextIO

from psyop.devices.photometers.base import Reading
from psyop.errors import UserError

MAX_TRIES = 3


def parse_typed(line: str) -> Reading | None:
    """The reading on a typed line, or None when it is not one.

    Examples
    --------
    >>> parse_typed("12.5 0.31, 0.33")
    Reading(luminance_cd_m2=12.5, x=0.31, y=0.33, raw='12.5 0.31, 0.33', quality=None)
    >>> parse_typed("bright") is None
    True
    """
    fields = [f for f in re.split(r"[\s,;]+", line.strip()) if f]
    try:
        values = [float(f) for f in fields]
    except ValueError:
        return None
    if len(values) not in (1, 3) or not all(math.isfinite(v) for v in values) or values[0] < 0:
        return None
    if len(values) == 3 and not (0 <= values[1] <= 1 and 0 <= values[2] <= 1):
        return None
    x, y = (values[1], values[2]) if len(values) == 3 else (None, None)
    return Reading(values[0], x, y, raw=line.strip())


class ManualPhotometer:
    """A person reads the meter and types each value."""

    interactive = True
    kind = "manual"

    def __init__(self, stdin: TextIO, prompt: TextIO, device_name: str | None = None) -> None:
        self.stdin, self.prompt, self.device_name = stdin, prompt, device_name
        self.label = "manual readings (stdin)"
        self.count = 0

    def measure(self) -> Reading:
        for _ in range(MAX_TRIES):
            line = self.stdin.readline()
            if not line:
                raise UserError(f"{self.label}: stdin ended after {self.count} readings; type one luminance in cd/m2 "
                                "per patch (optionally followed by x y), or feed a file with one line per patch, "
                                "then rerun")
            reading = parse_typed(line)
            if reading is not None:
                self.count += 1
                return reading
            print(f"not a reading: {line.strip()!r}; type the luminance in cd/m2, optionally followed by x y:",
                  file=self.prompt, flush=True)
        raise UserError(f"{self.label}: {MAX_TRIES} lines in a row were no reading; type one luminance in cd/m2 per "
                        "patch (optionally followed by x y), then rerun")

    def describe(self) -> dict:
        return {"kind": self.kind, "model": self.device_name, "port": None, "serial_number": None,
                "settings": "typed on stdin"}

    def close(self) -> None:
        return None
