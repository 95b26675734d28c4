"""Luminance in a protocol (docs/gratings_and_luminance.md): the display's calibration file and the checks of every
luminance and contrast a scene states.

``display: calibration: FILE`` (relative to the protocol) names a file ``psyop calibrate`` wrote; it is read when
the protocol is validated (a missing, unreadable, partial or corrupt file is one issue at that key's file:line:column)
and cached by path, size and modification time, so the scene builder reuses the same
:class:`psyop.optics.transfer.DisplayTransfer`. Surfaces may then state ``luminance: {cd_m2: ...}``; each value, and
each pattern's mean +- its Michelson amplitude, must lie in the calibrated range (the grey channel's luminance at
codes 0 and 255), for every level of a factor it names. Without a calibration any luminance is refused.

This module sits in psyop.protocol and reads the file itself (psyop.calibration is a layer above); its format name
is psyop.calibration.record.FORMAT (tests/protocol/test_luminance_protocol.py checks the two agree).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

from psyop.errors import UserError
from psyop.optics.transfer import DisplayTransfer
from psyop.protocol.scene import (
    Contrast,
    FactorRef,
    GratingSurface,
    ImageSurface,
    Mesh,
    PinkNoiseSurface,
    ReachMesh,
    ReachTarget,
    SolidSurface,
    WhiteNoiseSurface,
)
from psyop.records import JsonObject, Loc

if TYPE_CHECKING:
    from psyop.protocol.model import Protocol

#: the calibration file's format (psyop.calibration.record.FORMAT)
CALIBRATION_FORMAT = "psyop-display-calibration/1"
#: the largest calibration file read (a real one is a few hundred kB)
MAX_CALIBRATION_BYTES = 16 * 1024 * 1024

_CACHE: dict[tuple[str, int, int], DisplayTransfer] = {}


def calibration_path(protocol: Protocol, base_dir: Path | None) -> Path | None:
    """Where the protocol's calibration file is (None: an uncalibrated display)."""
    name = protocol.display.calibration
    if name is None:
        return None
    return (Path(base_dir) if base_dir is not None else Path.cwd()) / name


def load_transfer(path: Path) -> DisplayTransfer:
    """The display transfer of a calibration file (cached); a UserError saying what is wrong and the fix."""
    path = Path(path)
    try:
        stat = path.stat()
    except OSError as error:
        raise UserError(f"calibration file '{path}' not found ({error.strerror or error}); paths are relative to the "
                        "protocol file: fix the path or run psyop calibrate --out FILE") from None
    key = (str(path.resolve()), stat.st_size, stat.st_mtime_ns)
    cached = _CACHE.get(key)
    if cached is not None:
        return cached
    if not path.is_file() or stat.st_size > MAX_CALIBRATION_BYTES:
        raise UserError(f"calibration file '{path}' is not a regular file of at most {MAX_CALIBRATION_BYTES} bytes")
    try:
        record = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as error:
        raise UserError(f"calibration file '{path}' cannot be read as JSON ({error}); point to a file psyop "
                        "calibrate wrote") from None
    if not isinstance(record, dict) or record.get("format") != CALIBRATION_FORMAT:
        raise UserError(f"'{path}' is not a psyop display calibration (format {CALIBRATION_FORMAT} expected)")
    if record.get("complete") is not True:
        raise UserError(f"'{path}' is a partial calibration (the run stopped: {record.get('error', 'no error kept')}); "
                        "rerun psyop calibrate")
    try:
        transfer = DisplayTransfer.from_record(record, key=f"{key[0]}")
    except ValueError as error:
        raise UserError(f"calibration file '{path}': {error}") from None
    _CACHE.clear()  # one display per session: keep the newest only
    _CACHE[key] = transfer
    return transfer


def protocol_transfer(protocol: Protocol, base_dir: Path | None) -> DisplayTransfer | None:
    """The protocol's display transfer, or None without ``display: calibration``."""
    path = calibration_path(protocol, base_dir)
    return None if path is None else load_transfer(path)


def _luminance_surfaces(item: object) -> Iterable[tuple[str, object]]:
    for name in ("surface", "left", "right"):
        surface = getattr(item, name, None)
        if surface is not None:
            yield name, surface


def _pattern_range(surface: object) -> tuple[float, float] | None:
    """(lowest, highest) luminance of a surface with a resolved luminance (None: no luminance, or a factor)."""
    luminance = getattr(surface, "luminance", None)
    if luminance is None or isinstance(luminance.cd_m2, FactorRef):
        return None
    mean = float(luminance.cd_m2)
    if isinstance(surface, GratingSurface):
        contrast = surface.michelson
        if isinstance(contrast, FactorRef):
            return None
        return mean * (1.0 - float(contrast)), mean * (1.0 + float(contrast))
    return mean, mean


def luminance_issues(protocol: Protocol, base_dir: Path | None,
                     value_sets: Iterable[JsonObject]) -> list[tuple[Loc, str]]:
    """Every problem with the display's calibration and the scene's luminances, as (key path, message)."""
    from psyop.protocol.factor_fields import resolve_factor_fields

    issues: list[tuple[Loc, str]] = []
    transfer: DisplayTransfer | None = None
    try:
        transfer = protocol_transfer(protocol, base_dir)
    except UserError as error:
        issues.append((("display", "calibration"), error.message))
        return issues
    sets = list(value_sets) or [{}]
    for index, item in enumerate(protocol.scene):
        path: Loc = ("scene", index)
        if transfer is not None and (isinstance(item, Mesh) or
                                     (isinstance(item, ReachTarget) and isinstance(item.object, ReachMesh))):
            issues.append((path, "a glTF model's colours are pixel values, not linearised on a calibrated display "
                                 "(display: calibration); remove the calibration or the model"))
        for name, surface in _luminance_surfaces(item):
            where = path + (name,)
            if transfer is not None and isinstance(surface, ImageSurface):
                issues.append((where + ("path",), "image surfaces hold pixel values, which are not linearised on a "
                                                  "calibrated display (display: calibration); use a grating, noise or "
                                                  "a solid luminance"))
            if getattr(surface, "luminance", None) is None:
                continue
            if transfer is None:
                issues.append((where + ("luminance",), "a luminance needs a calibrated display: add display: "
                                                       "calibration: FILE (psyop calibrate --out FILE), or give "
                                                       "the surface as pixel values (rgb, mean)"))
                continue
            low, high = transfer.black_cd_m2, transfer.peak_cd_m2
            for values in sets:
                try:
                    resolved = resolve_factor_fields(surface, values)
                except ValueError:  # an adaptive level known only at run time, or a bad level (reported elsewhere)
                    continue
                span = _pattern_range(resolved)
                if span is None:
                    continue
                if span[0] < low * (1 - 1e-9) or span[1] > high * (1 + 1e-9):
                    what = ("its luminance" if isinstance(resolved, (SolidSurface, WhiteNoiseSurface, PinkNoiseSurface))
                            else "its mean +- the Michelson amplitude")
                    shown = f"{span[0]:.4g} cd/m²" if span[0] == span[1] else f"{span[0]:.4g} to {span[1]:.4g} cd/m²"
                    level = "" if not values else " for " + ", ".join(
                        f"{k} = {v!r}" for k, v in values.items() if k in _factor_names(surface))
                    issues.append((where + ("luminance", "cd_m2"),
                                   f"{what} spans {shown}{level}, outside the calibrated range {low:.4g} to "
                                   f"{high:.4g} cd/m² (the grey channel at codes 0 and 255 of "
                                   f"{protocol.display.calibration}); lower the luminance or the contrast"))
                    break
    return issues


def _factor_names(surface: object) -> set[str]:
    from psyop.protocol.factor_fields import factor_fields

    return {ref.factor for _, ref in factor_fields(surface)}


def nyquist_cycles_per_deg(protocol: Protocol) -> float:
    """Half the display's sampling rate at its centre, cycles per degree: ``0.5 / degrees(tangent per pixel)`` for the
    coarser of its two axes (a grating above it aliases on every pixel)."""
    from psyop.protocol.display import resolve_display_profile

    display = resolve_display_profile(protocol.display)
    per_px = max((display.tan_right - display.tan_left) / display.width_px,
                 (display.tan_top - display.tan_bottom) / display.height_px)
    return 0.5 / math.degrees(per_px)


def grating_issues(protocol: Protocol, value_sets: Iterable[JsonObject]) -> list[tuple[Loc, str]]:
    """Gratings above the display's Nyquist frequency (at its centre, where a pixel subtends the most), refused."""
    from psyop.protocol.factor_fields import resolve_factor_fields

    limit: float | None = None
    issues: list[tuple[Loc, str]] = []
    sets = list(value_sets) or [{}]
    for index, item in enumerate(protocol.scene):
        for name, surface in _luminance_surfaces(item):
            if not isinstance(surface, GratingSurface):
                continue
            issues += _log_contrast_issues(surface, ("scene", index, name, "contrast"))
            limit = nyquist_cycles_per_deg(protocol) if limit is None else limit
            for values in sets:
                try:
                    cpd = float(resolve_factor_fields(surface, values).cycles_per_deg)
                except (ValueError, TypeError):
                    continue
                if cpd > limit:
                    issues.append((("scene", index, name, "cycles_per_deg"),
                                   f"{cpd:g} cycles/deg is above the display's Nyquist frequency at its centre "
                                   f"({limit:.3g} cycles/deg: half a cycle per pixel); the grating would alias. "
                                   "Lower cycles_per_deg"))
                    break
    return issues


def _log_contrast_issues(surface: GratingSurface, where: Loc) -> list[tuple[Loc, str]]:
    """A grating's contrast read from a factor in the right units: ``michelson_log10`` from a factor named
    ``*_log10``, and a log10 factor never read as a linear contrast (``contrast: {factor: x_log10}``)."""
    contrast = surface.contrast
    if isinstance(contrast, Contrast) and isinstance(contrast.michelson_log10, FactorRef):
        ref = contrast.michelson_log10.factor
        if not ref.endswith("_log10"):
            return [(where + ("michelson_log10",), f"michelson_log10 reads factor '{ref}' as log10 units, but its "
                                                   "name says another unit; name the factor '..._log10' (its levels "
                                                   "are log10 Michelson contrasts, e.g. -2 for 1 %)")]
        return []
    linear = contrast.michelson if isinstance(contrast, Contrast) and contrast.michelson is not None else \
        contrast.weber if isinstance(contrast, Contrast) else contrast
    key = where + ((("michelson",) if contrast.michelson is not None else ("weber",))
                   if isinstance(contrast, Contrast) else ())
    if isinstance(linear, FactorRef) and linear.factor.endswith("_log10"):
        return [(key, f"factor '{linear.factor}' is in log10 units but is read here as a linear contrast; write "
                      f"contrast: {{michelson_log10: {{factor: {linear.factor}}}}}")]
    return []


#: How an uncalibrated session's 8-bit output relates to the protocol's values (docs/protocols.md, "The linearised
#: output")
UNCALIBRATED_OUTPUT = ("pixel values: code = round(255 v), no transfer function applied (no gamma, no sRGB "
                       "encoding); luminances and contrasts on the screen are unknown")


def output_record(protocol: Protocol, base_dir: Path | None) -> JsonObject:
    """session.json's ``display_output``: whether the session's stimuli were linearised through a display
    calibration, and which (its file, SHA-256, grey model, black and peak luminance, the final pass's method), or
    that they were written as pixel values on an uncalibrated display."""
    import hashlib

    path = calibration_path(protocol, base_dir)
    if path is None:
        return {"calibrated": False, "output": UNCALIBRATED_OUTPUT}
    transfer = load_transfer(path)
    record = json.loads(path.read_text())
    grey = record.get("fit", {}).get("grey", {})
    return {"calibrated": True, "calibration_file": protocol.display.calibration,
            "calibration_sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
            "calibration_date": record.get("date"), "device": record.get("device", {}).get("model"),
            "display": record.get("display", {}).get("name"), "model": grey.get("model"),
            "black_cd_m2": transfer.black_cd_m2, "peak_cd_m2": transfer.peak_cd_m2,
            "output": "normalised luminance through the grey channel's inverse (a table every 1/64 code), then an "
                      "8 x 8 ordered spatio-temporal dither to 8-bit codes"}
