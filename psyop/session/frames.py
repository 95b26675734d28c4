"""Per-frame records: rendering (or its stand-in), submission, and latency accounting.

A frame's latency is the age of the gaze sample it used at the moment the frame was
submitted (``submit_s - gaze_sample_t_s``): tracker latency + waiting + the software path.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import pyarrow as pa

from psyop.optics.display import DisplayProfile
from psyop.optics.rig import EyeRig
from psyop.session.log.schema import FRAME_SCHEMA


#: A head pose: position (m) and unit quaternion (w, x, y, z), head -> world (session start).
HeadPose = tuple[tuple[float, float, float], tuple[float, float, float, float]]

@dataclass(frozen=True)
class FrameCheck:
    """What a renderer reports: whether an image was rendered and checked (finite, not
    blank), and whether the frame (image and cameras) was fine."""

    checked: bool
    ok: bool


class FrameRenderer(Protocol):
    """Renders one frame for a fixation; returns a check of the result.

    ``phase`` says what is shown (its ``name``: 'interval1', 'blank', ...; ``show``),
    ``mode`` the loop's rendering mode for it, ``t_in_phase_s`` the time since the phase began.
    """

    def render(self, row: Mapping[str, Any], phase: Any, mode: str, t_in_phase_s: float,
               fixation_m: tuple[float, float, float], head_pose: HeadPose | None = None) -> FrameCheck: ...


class Display(Protocol):
    """Where frames go: ``submit`` presents the frame and returns the flip time (session clock)."""

    def submit(self) -> float: ...

    def close(self) -> None: ...


class CameraRenderer:
    """Computes the cameras of the rig's eye(s) (psyop.optics.rig) for each frame; checks they
    are finite. This is the gaze-dependent part of every frame, without an image."""

    def __init__(self, display: DisplayProfile, rig: EyeRig) -> None:
        self.display, self.rig = display, rig

    def render(self, row: Mapping[str, Any], phase: Any, mode: str, t_in_phase_s: float,
               fixation_m: tuple[float, float, float], head_pose: HeadPose | None = None) -> FrameCheck:
        ok = True  # cameras are in head space: the head pose changes no camera
        for eye in self.rig.eyes:
            camera = self.rig.camera(self.display, eye, fixation_m, mode)
            ok &= bool(np.isfinite(camera.view).all() and np.isfinite(camera.projection).all())
        return FrameCheck(False, ok)  # no image was made


class HeadlessDisplay:
    """No screen: a frame is 'submitted' when the renderer returns."""

    def __init__(self, clock: Any) -> None:
        self._clock = clock

    def submit(self) -> float:
        return self._clock.now_s()

    def close(self) -> None:
        return None


class FrameRecorder:
    """Collects one trial's frame rows column-wise; cheap to append, one batch per trial."""

    def __init__(self) -> None:
        self._cols: dict[str, list[Any]] = {name: [] for name in FRAME_SCHEMA.names}

    def add(self, **values: Any) -> None:
        for name, column in self._cols.items():
            column.append(values.get(name))

    def __len__(self) -> int:
        return len(self._cols["trial"])

    def table(self) -> pa.Table:
        return pa.Table.from_pydict(self._cols, schema=FRAME_SCHEMA)


def latency_summary(sample_age_s: np.ndarray, frame_period_s: float) -> dict[str, float]:
    """Median / p95 / p99 / max of the sample age at flip, in ms and in frames."""
    ages = np.asarray(sample_age_s, dtype=np.float64)
    ages = ages[np.isfinite(ages)]
    if ages.size == 0:
        return {"n_frames": 0}
    q = np.percentile(ages, [50, 95, 99]) * 1e3
    return {
        "n_frames": int(ages.size),
        "sample_age_median_ms": float(q[0]),
        "sample_age_p95_ms": float(q[1]),
        "sample_age_p99_ms": float(q[2]),
        "sample_age_max_ms": float(ages.max() * 1e3),
        "sample_age_median_frames": float(q[0] / (frame_period_s * 1e3)) if frame_period_s > 0 else math.nan,
    }
