"""The luminance and contrast each stimulus actually gets after quantisation, on a calibrated display
(docs/calibration.md): part of ``psyop audit``'s output. The measurement (each luminance primitive alone through the
final pass, its wholly covered pixels, achieved against intended) is :mod:`psyop.stimulus.achieved`, which a session
also uses for session.json; this module lays out the audit's table.
"""

from __future__ import annotations

from psyop.stimulus.achieved import LuminanceCheck, luminance_checks

__all__ = ["LuminanceCheck", "luminance_checks", "luminance_table"]


def luminance_table(checks: list[tuple[str, LuminanceCheck]]) -> list[str]:
    """Lines of the audit's luminance table: per frame label and primitive, intended and achieved."""
    if not checks:
        return []
    lines = ["luminance after quantisation (calibrated display; one frame, fully covered pixels):",
             f"{'frame':<40} {'primitive':<16} {'pixels':>7} {'mean cd/m2 intended':>20} {'achieved':>9} "
             f"{'contrast % intended':>20} {'achieved':>9}"]
    for label, c in checks:
        lines.append(f"{label:<40} {c.name:<16} {c.pixels:>7d} {c.intended_cd_m2:>20.4f} {c.achieved_cd_m2:>9.4f} "
                     f"{100 * c.intended_contrast:>20.4f} {100 * c.achieved_contrast:>9.4f}")
    return lines
