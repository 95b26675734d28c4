"""Photometer adapters for ``psyop calibrate`` (docs/calibration.md), each speaking its device's own documented
serial protocol over pyserial, and typed readings:

- ``ls100:PORT`` / ``ls110:PORT``: Konica Minolta LS-100 / LS-110 (:mod:`.minolta`);
- ``pr650:PORT``: Photo Research PR-650; ``pr655:PORT`` / ``pr670:PORT``: PR-655 / PR-670 (:mod:`.photo_research`);
- ``colorcal:PORT``: CRS ColorCAL MKII (:mod:`.colorcal`);
- ``manual``: a person types each reading on stdin (:mod:`.manual`).

Each adapter has ``label`` (what every message names), ``interactive``, ``describe()`` (the calibration file's
``device``), ``measure()`` (a :class:`~.base.Reading`) and ``close()``; every fault is a one-line
:class:`~psyop.errors.UserError` naming the device and the fix. The calibration run (psyop.calibration.measure)
takes them through its structural ``Photometer`` protocol: this package never imports psyop.calibration.
"""

from __future__ import annotations

import sys
from typing import TextIO

from psyop.errors import UserError

KINDS = ("ls100", "ls110", "pr650", "pr655", "pr670", "colorcal", "manual")
USAGE = "ls100:PORT, ls110:PORT, pr650:PORT, pr655:PORT, pr670:PORT, colorcal:PORT or manual"


def open_photometer(spec: str, *, timeout_s: float | None = None, stdin: TextIO | None = None,
                    prompt: TextIO | None = None, device_name: str | None = None):  # -> the adapter
    """The adapter ``spec`` names (``KIND:PORT`` or ``manual``), opened and checked."""
    kind, _, port = spec.partition(":")
    kind = kind.lower()
    if kind == "manual":
        from psyop.devices.photometers.manual import ManualPhotometer

        return ManualPhotometer(sys.stdin if stdin is None else stdin, sys.stderr if prompt is None else prompt,
                                device_name)
    if kind not in KINDS or not port:
        raise UserError(f"--photometer must be {USAGE}, got {spec!r}")
    timeouts = {} if timeout_s is None else {"timeout_s": timeout_s}
    if kind in ("ls100", "ls110"):
        from psyop.devices.photometers.minolta import MinoltaLS100

        return MinoltaLS100(port, kind=kind, **timeouts)
    if kind == "colorcal":
        from psyop.devices.photometers.colorcal import ColorCal

        return ColorCal(port, **timeouts)
    from psyop.devices.photometers.photo_research import PR650, PR655

    if kind == "pr650":
        return PR650(port, **timeouts)
    return PR655(port, kind=kind, **timeouts)
