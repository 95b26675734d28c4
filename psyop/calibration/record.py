"""The calibration file ``psyop calibrate --out CAL.json`` writes (format ``psyop-display-calibration/1``).

One JSON object, written atomically (:func:`psyop.atomic.write_atomic`)::

    format        "psyop-display-calibration/1"
    complete      true; false in the partial file a fault leaves (``CAL.partial.json``), with ``error``
    date          UTC, ISO 8601, when the run started
    display       what showed the patches: kind (headless | window), size_px, name (``--display-name``)
    device        the photometer: kind (ls100, pr650, pr655, manual), model, port, serial_number (null where the
                  device reports none: LS-100, PR-650, manual), settings (baud rate, framing), model_reported
    bits, levels, repeats, channels
                  8-bit codes (0..255) shown per channel; each (channel, level) shown ``repeats`` times
    readings      one per patch, in the order shown: index, channel, code, rgb, repeat, luminance_cd_m2, x, y
                  (CIE 1931 chromaticity, null where the device gives none), raw (the device's reply), quality
                  (the device's flag, e.g. PR-650 "low light"), time_s (seconds since the run started)
    fit           per channel (complete files only): model (gog | spline), gog {black_cd_m2, gain_cd_m2, offset,
                  gamma, offset_fitted, rms_relative, loo_rms_relative}, spline {kind pchip, codes,
                  luminance_cd_m2, rms_relative, loo_rms_relative}, levels [{code, mean_cd_m2, sd_cd_m2,
                  predicted_cd_m2, residual_relative}], residuals_cd_m2 and residuals_relative (per reading of the
                  channel, in order), max_abs_residual_relative (psyop.calibration.model)
    luminance_cd_m2  {min, max}: the lowest and highest level mean
    chromaticity  per channel the mean CIE x, y at full level (255), where the device measured them
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from psyop.atomic import write_atomic
from psyop.errors import UserError

FORMAT = "psyop-display-calibration/1"


def partial_path(out: Path) -> Path:
    """Where a fault leaves the readings so far: ``CAL.json`` -> ``CAL.partial.json``."""
    out = Path(out)
    return out.with_name(f"{out.stem}.partial{out.suffix or '.json'}")


def _finite_or_none(value: object) -> object:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_record(path: Path, record: dict) -> Path:
    """Write ``record`` (JSON, NaN as null) to ``path`` atomically."""
    text = json.dumps(record, indent=1, default=_finite_or_none, allow_nan=False) + "\n"
    return write_atomic(Path(path), text)


def summary(readings: list[dict], channels: tuple[str, ...]) -> tuple[dict, dict]:
    """(luminance {min, max} over the level means, chromaticity per channel at full level where measured)."""
    means: list[float] = []
    chromaticity: dict[str, dict[str, float]] = {}
    for channel in channels:
        own = [r for r in readings if r["channel"] == channel]
        for code in sorted({r["code"] for r in own}):
            values = [r["luminance_cd_m2"] for r in own if r["code"] == code]
            means.append(sum(values) / len(values))
        full = [r for r in own if r["code"] == 255 and r.get("x") is not None and r.get("y") is not None]
        if full:
            chromaticity[channel] = {"x": sum(r["x"] for r in full) / len(full),
                                     "y": sum(r["y"] for r in full) / len(full)}
    extremes = {"min": min(means), "max": max(means)} if means else {"min": None, "max": None}
    return extremes, chromaticity


def load_calibration(path: Path) -> dict:
    """A complete calibration file, checked for its format (a UserError naming the file otherwise)."""
    try:
        record = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise UserError(f"cannot read the calibration ({exc}); point to a file psyop calibrate wrote", str(path)) from exc
    if not isinstance(record, dict) or record.get("format") != FORMAT:
        raise UserError(f"not a psyop display calibration (format {FORMAT} expected)", str(path))
    if not record.get("complete"):
        raise UserError("a partial calibration (the run stopped: see its error); rerun psyop calibrate", str(path))
    return record
