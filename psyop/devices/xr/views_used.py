"""What an OpenXR runtime really showed: per-eye swapchain size, fields of view and the measured display rate.

A protocol names a display profile (e.g. ``vive_pro``, 1440x1600 per eye at 90 Hz), but on a headset the
runtime decides: the swapchain size it recommends per eye, the field of view of each eye's view at every
display time (``xrLocateViews``), and the display times it predicts (``xrWaitFrame``), whose spacing is the
rate frames reach the display. :class:`ViewsSeen` collects these as the session runs (one call per frame)
and :meth:`ViewsSeen.record` writes them as session.json's ``display_used`` block of the run (docs/data.md),
which the BIDS export reads (``StimulusPresentation``, gaze pixel coordinates).

The measured rate is 1 / the median interval between consecutive predicted display times (a missed frame
is one long interval: the median is the display's rate, not the loop's); the runtime's own predicted
display period is recorded beside it. A field of view is recorded as the first frame's; a runtime that
changes it later (an IPD or eye-relief change) is counted (``fov_frames_changed``) with the largest change
of any tangent, never averaged away.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Sequence
from dataclasses import dataclass, field

from psyop.optics.camera import ViewGeometry
from psyop.session.rows import JsonObject

#: a tangent that moved by less than this between frames is the same field of view (float32 round trip)
FOV_TOLERANCE_TAN = 1e-6


@dataclass
class ViewsSeen:
    """Per-eye fields of view and predicted display times seen during one run (module docstring)."""

    tangents: dict[str, tuple[float, float, float, float]] = field(default_factory=dict)
    orientations_wxyz: dict[str, tuple[float, float, float, float]] = field(default_factory=dict)
    fov_frames_changed: int = 0
    fov_max_change_tan: float = 0.0
    _display_ns: int | None = None
    _intervals_s: array = field(default_factory=lambda: array("d"))
    _periods_s: array = field(default_factory=lambda: array("d"))

    def add_frame(self, display_time_ns: int, period_ns: int) -> None:
        """One xrWaitFrame: its predicted display time and period (ns)."""
        if self._display_ns is not None and display_time_ns > self._display_ns:
            self._intervals_s.append((display_time_ns - self._display_ns) * 1e-9)
        self._display_ns = display_time_ns
        if period_ns > 0:
            self._periods_s.append(period_ns * 1e-9)

    def add_views(self, views: Sequence[ViewGeometry]) -> None:
        """Each eye's view located for the frame (head space: the image's orientation and tangents)."""
        changed = False
        for view in views:
            eye, tangents = view.eye, view.tangents
            self.orientations_wxyz.setdefault(eye, view.orientation_wxyz)
            first = self.tangents.setdefault(eye, tangents)
            change = max(abs(a - b) for a, b in zip(first, tangents))
            if change > FOV_TOLERANCE_TAN:
                changed = True
                self.fov_max_change_tan = max(self.fov_max_change_tan, change)
        self.fov_frames_changed += int(changed)

    def record(self, sizes_px: Sequence[tuple[int, int]], runtime: str, system: str) -> JsonObject:
        """session.json's ``display_used`` of the run (docs/data.md)."""
        eyes: JsonObject = {}
        for eye, (w, h) in zip(("left", "right"), sizes_px):
            entry: JsonObject = {"width_px": int(w), "height_px": int(h)}
            tangents = self.tangents.get(eye)
            if tangents is not None:
                entry.update(zip(("tan_left", "tan_right", "tan_bottom", "tan_top"), tangents))
                entry["fov_deg"] = {"left": math.degrees(math.atan(tangents[0])),
                                    "right": math.degrees(math.atan(tangents[1])),
                                    "down": math.degrees(math.atan(tangents[2])),
                                    "up": math.degrees(math.atan(tangents[3]))}
                entry["orientation_wxyz"] = list(self.orientations_wxyz[eye])  # identity: the image is not canted
            eyes[eye] = entry
        interval = _median(self._intervals_s)
        return {
            "display": "openxr", "runtime": runtime, "system": system,
            "measured": bool(self.tangents),  # false: no frame was located (the run ended before its first)
            "source": "the OpenXR runtime: swapchain size per eye (xrEnumerateViewConfigurationViews, recommended), "
                      "field of view per eye (xrLocateViews, first frame), rate from the predicted display times "
                      "(xrWaitFrame)",
            "eyes": eyes,
            "fov_frames_changed": self.fov_frames_changed, "fov_max_change_tan": self.fov_max_change_tan,
            "refresh_hz": 1.0 / interval if interval > 0 else None,
            "display_interval_median_s": interval if interval > 0 else None,
            "predicted_period_median_s": _median(self._periods_s) or None,
            "display_intervals_measured": len(self._intervals_s),
        }


def _median(values: array) -> float:
    """The median of ``values`` (0.0 for none)."""
    if not len(values):
        return 0.0
    ordered = sorted(values)
    mid = len(ordered) // 2
    return float(ordered[mid]) if len(ordered) % 2 else float(0.5 * (ordered[mid - 1] + ordered[mid]))
