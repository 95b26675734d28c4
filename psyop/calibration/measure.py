"""One calibration run: every patch shown, then read; the readings checked, fitted and written.

The photometer and the patch display are structural protocols (:class:`Photometer`, :class:`PatchDisplay`): the
adapters in psyop.devices.photometers and psyop.calibration.patches implement them, and psyop.cli.calibrate
wires them, so this package never imports psyop.devices.

A fault (a :class:`~psyop.errors.UserError` from the device or the display: a timeout, an error reply, garbage,
a pulled cable; or readings that are non-monotone or noisy) ends the run with one line naming the device and the
fix, exit 2, and the readings so far written to the partial file (``CAL.partial.json``, ``complete: false``,
with the ``error``) named in that line. Ctrl-C keeps them the same way.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Protocol, TextIO

from psyop.calibration.model import CHANNELS, check_readings, fit_channel
from psyop.calibration.patches import Rgb, patch_rgb, patch_sequence
from psyop.calibration.record import FORMAT, partial_path, summary, write_record
from psyop.errors import UserError


class Reading(Protocol):
    @property
    def luminance_cd_m2(self) -> float: ...
    @property
    def x(self) -> float | None: ...
    @property
    def y(self) -> float | None: ...
    @property
    def raw(self) -> str: ...
    @property
    def quality(self) -> str | None: ...


class Photometer(Protocol):
    label: str  # "ls100 on /dev/ttyUSB0": what every message names
    interactive: bool  # a person types the readings (the run prompts for each patch)

    def describe(self) -> dict: ...

    def measure(self) -> Reading: ...

    def close(self) -> None: ...


class PatchDisplay(Protocol):
    def show(self, rgb: Rgb) -> Rgb: ...

    def describe(self) -> dict: ...

    def close(self) -> None: ...


@dataclass(frozen=True)
class CalibrationPlan:
    codes: list[int]
    repeats: int
    out: Path
    display_name: str | None = None
    channels: tuple[str, ...] = CHANNELS


class _Progress:
    """A tqdm bar on a terminal; plain lines (start, each tenth, end) otherwise; nothing when off."""

    def __init__(self, total: int, enabled: bool, stream: TextIO) -> None:
        self.total, self.done, self.stream, self.bar = total, 0, stream, None
        self.enabled = enabled
        self.step = max(1, -(-total // 10))
        if enabled and getattr(stream, "isatty", lambda: False)():
            from tqdm import tqdm

            self.bar = tqdm(total=total, file=stream, unit="patch", desc="calibrate", dynamic_ncols=True)
        elif enabled:
            print(f"calibrate: 0/{total} patches", file=stream, flush=True)

    def update(self) -> None:
        self.done += 1
        if self.bar is not None:
            self.bar.update(1)
        elif self.enabled and (self.done % self.step == 0 or self.done == self.total):
            print(f"calibrate: {self.done}/{self.total} patches", file=self.stream, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def _header(photometer: Photometer, display: PatchDisplay, plan: CalibrationPlan, date: str) -> dict:
    return {"format": FORMAT, "complete": False, "date": date,
            "display": {**display.describe(), "name": plan.display_name},
            "device": photometer.describe(), "bits": 8, "levels": list(plan.codes), "repeats": plan.repeats,
            "channels": list(plan.channels)}


def _keep_partial(record: dict, readings: list[dict], out: Path, error: str) -> Path:
    partial = partial_path(out)
    write_record(partial, {**record, "complete": False, "error": error, "readings": readings})
    return partial


def _read_all(photometer: Photometer, display: PatchDisplay, plan: CalibrationPlan, readings: list[dict],
              progress: bool, prompt: TextIO) -> None:
    sequence = patch_sequence(plan.codes, plan.repeats, plan.channels)
    bar = _Progress(len(sequence), progress and not photometer.interactive, prompt)
    start = time.monotonic()
    try:
        for index, (channel, code, repeat) in enumerate(sequence):
            rgb = display.show(patch_rgb(channel, code))
            if photometer.interactive:
                print(f"patch {index + 1}/{len(sequence)}: {channel} {code}/255 (rgb {rgb[0]},{rgb[1]},{rgb[2]}); "
                      "type the luminance in cd/m2 (optionally followed by CIE x y):", file=prompt, flush=True)
            reading = photometer.measure()
            readings.append({"index": index, "channel": channel, "code": code, "rgb": list(rgb), "repeat": repeat,
                             "luminance_cd_m2": reading.luminance_cd_m2, "x": reading.x, "y": reading.y,
                             "raw": reading.raw, "quality": reading.quality,
                             "time_s": round(time.monotonic() - start, 4)})
            bar.update()
    finally:
        bar.close()


def _fit(record: dict, readings: list[dict], channels: Sequence[str], label: str) -> dict:
    for channel in channels:
        own = [r for r in readings if r["channel"] == channel]
        check_readings(channel, [r["code"] for r in own], [r["luminance_cd_m2"] for r in own], label)
    fits = {}
    for channel in channels:
        own = [r for r in readings if r["channel"] == channel]
        fits[channel] = fit_channel([r["code"] for r in own], [r["luminance_cd_m2"] for r in own])
    extremes, chromaticity = summary(readings, tuple(channels))
    return {**record, "complete": True, "readings": readings, "fit": fits, "luminance_cd_m2": extremes,
            "chromaticity": chromaticity}


def run_calibration(photometer: Photometer, display: PatchDisplay, plan: CalibrationPlan, *,
                    progress: bool = True, prompt: TextIO | None = None) -> dict:
    """Show, read, check, fit and write; return the record written to ``plan.out``."""
    prompt = sys.stderr if prompt is None else prompt
    date = datetime.now(timezone.utc).isoformat(timespec="seconds")
    record = _header(photometer, display, plan, date)
    readings: list[dict] = []
    try:
        _read_all(photometer, display, plan, readings, progress, prompt)
        complete = _fit(record, readings, plan.channels, photometer.label)
    except UserError as error:
        partial = _keep_partial(record, readings, plan.out, str(error))
        raise UserError(f"{error}; the {len(readings)} readings so far are kept in {partial}") from None
    except KeyboardInterrupt:
        partial = _keep_partial(record, readings, plan.out, "interrupted")
        print(f"psyop calibrate: the {len(readings)} readings so far are kept in {partial}", file=sys.stderr)
        raise
    write_record(plan.out, complete)
    partial_path(plan.out).unlink(missing_ok=True)  # a former run's partial file is superseded
    return complete
