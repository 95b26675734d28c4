"""Calibration files of displays with a known transfer, written with psyop.calibration's own model and record
functions (what ``psyop calibrate`` writes), for the luminance tests (docs/gratings_and_luminance.md)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from psyop.calibration.model import CHANNELS, fit_channel
from psyop.calibration.record import FORMAT, summary, write_record

#: Rec. 709 luminance weights of the red, green and blue primaries (the emulated display of tests/calibration)
WEIGHTS = {"grey": 1.0, "red": 0.2126, "green": 0.7152, "blue": 0.0722}


def power_law(gamma: float = 2.4, black_cd_m2: float = 0.3, peak_cd_m2: float = 100.0) -> Callable[[np.ndarray], np.ndarray]:
    """The known display: ``L(code) = black + (peak - black) (code / 255) ** gamma``, cd/m²."""
    return lambda code: black_cd_m2 + (peak_cd_m2 - black_cd_m2) * (np.asarray(code, dtype=np.float64) / 255.0) ** gamma


def s_shaped(black_cd_m2: float = 0.5, peak_cd_m2: float = 120.0) -> Callable[[np.ndarray], np.ndarray]:
    """A transfer no power law fits (a logistic in the code), so psyop calibrate keeps the spline."""
    def transfer(code: np.ndarray) -> np.ndarray:
        v = np.asarray(code, dtype=np.float64) / 255.0
        s = 1.0 / (1.0 + np.exp(-10.0 * (v - 0.5)))
        s0, s1 = 1.0 / (1.0 + np.exp(5.0)), 1.0 / (1.0 + np.exp(-5.0))
        return black_cd_m2 + (peak_cd_m2 - black_cd_m2) * (s - s0) / (s1 - s0)
    return transfer


def write_calibration(path: Path, transfer: Callable[[np.ndarray], np.ndarray], levels: int = 17) -> Path:
    """A complete calibration file of a display whose grey channel follows ``transfer`` (each primary its Rec. 709
    share above the black), one noise-free reading per level, fitted by psyop.calibration.model.fit_channel."""
    codes = np.round(np.linspace(0, 255, levels)).astype(int)
    readings = []
    for channel in CHANNELS:
        black = float(transfer(np.array(0.0)))
        luminance = black + WEIGHTS[channel] * (transfer(codes) - black)
        for code, value in zip(codes, luminance, strict=True):
            rgb = [int(code)] * 3 if channel == "grey" else [int(code) if c == channel else 0 for c in ("red", "green", "blue")]
            readings.append({"index": len(readings), "channel": channel, "code": int(code), "rgb": rgb, "repeat": 0,
                             "luminance_cd_m2": float(value), "x": None, "y": None, "raw": f"{value:.6g}",
                             "quality": None, "time_s": 0.0})
    fit = {channel: fit_channel([r["code"] for r in readings if r["channel"] == channel],
                                [r["luminance_cd_m2"] for r in readings if r["channel"] == channel])
           for channel in CHANNELS}
    extremes, chromaticity = summary(readings, CHANNELS)
    record = {"format": FORMAT, "complete": True, "date": "2026-12-07T00:00:00Z",
              "display": {"kind": "headless", "size_px": [64, 64], "name": "known display"},
              "device": {"kind": "manual", "model": "test", "port": None, "serial_number": None},
              "bits": 8, "levels": codes.tolist(), "repeats": 1, "channels": list(CHANNELS), "readings": readings,
              "fit": fit, "luminance_cd_m2": extremes, "chromaticity": chromaticity}
    return write_record(path, record)
