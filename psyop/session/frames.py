"""The frame seam: where frames go (:class:`Display`), what renders them (:class:`FrameRenderer`),
per-frame records and latency accounting.

Every frame goes through the same two calls, whatever the display (headless, a desktop window, an
OpenXR headset):

1. ``request = display.begin_frame(not_before_s)``: the display paces the loop (a headless display
   waits on the session clock until ``not_before_s``; a headset runtime blocks in ``xrWaitFrame``
   until it wants the next frame) and says when the frame will be shown (``display_time_s``,
   session clock; never before ``not_before_s``). It hands out the frame that is due when it is
   asked: a loop that comes late (the last frame took longer than a period) gets a frame for the
   display's current time, not for the slot it asked for, and ``missed_frames`` counts the display
   periods skipped in between (the stimulus follows the display clock: durations and motion stay
   right), the display period, whether to render at all, and, for a headset, each eye's
   view (centre, orientation, field of view: :class:`psyop.optics.camera.ViewGeometry`) and the
   render target (a swapchain image) each eye must be drawn into;
2. the renderer draws the eyes for that request (into the targets it was handed, if any);
3. ``submit_s = display.end_frame(request, images)``: the display presents the frame (a window
   shows ``images``, the renderer's eye textures; a headset releases its swapchain images and
   ends the frame) and returns the time the frame was handed over.

A frame's latency is the age of the gaze sample it used at the moment the frame was
submitted (``submit_s - gaze_sample_t_s``): tracker latency + waiting + the software path; its
gaze-to-photon estimate is the age at the predicted display time (``display_time_s - gaze_sample_t_s``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, TYPE_CHECKING

import numpy as np
import pyarrow as pa

from psyop.session.rows import JsonObject, TrialRow
from psyop.optics.camera import ViewGeometry
from psyop.optics.display import DisplayProfile
from psyop.optics.rig import EyeRig
from psyop.session.log.schema import FRAME_SCHEMA

if TYPE_CHECKING:
    import moderngl
    
    from psyop.session.clock import Clock
    from psyop.session.phases import PhaseSpec


#: A head pose: position (m) and unit quaternion (w, x, y, z), head -> world (session start).
HeadPose = tuple[tuple[float, float, float], tuple[float, float, float, float]]

@dataclass(frozen=True)
class FrameCheck:
    """What a renderer reports: whether an image was rendered and checked (finite, not
    blank), and whether the frame (image and cameras) was fine."""

    checked: bool
    ok: bool


@dataclass(frozen=True)
class RenderTarget:
    """Where one eye's image must go: a framebuffer the display owns (an OpenXR swapchain image,
    wrapped as a moderngl framebuffer) and its size in pixels. The renderer draws the eye at this
    size and copies the finished image into it."""

    framebuffer: moderngl.Framebuffer  # moderngl is imported only where a context exists
    width_px: int
    height_px: int


@dataclass(frozen=True)
class FrameRequest:
    """What the display asks for the next frame (see the module docstring).

    ``views`` (per eye, in head space) is empty when the protocol's display profile and eye rig
    place the cameras (headless, window); ``targets`` is empty when the images stay in the
    renderer's own buffers. ``missed_frames``: display periods skipped before this frame: for the
    headless display and a window, the periods between the slot the loop asked for and this frame's
    display time; for a headset, from the runtime's successive predicted display times."""

    index: int
    display_time_s: float
    period_s: float
    should_render: bool = True
    views: tuple[ViewGeometry, ...] = ()
    targets: Mapping[str, RenderTarget] = field(default_factory=dict, compare=False)
    missed_frames: int = 0

    def view(self, eye: str) -> ViewGeometry | None:
        """This eye's view from the display, or None (the profile and rig place it)."""
        for v in self.views:
            if v.eye == eye:
                return v
        return None


class DisplayInterrupted(Exception):
    """The display cannot show the trial in progress (an OpenXR session lost focus, or the runtime
    is stopping). The trial is discarded like a crashed one. ``rerun``: the display will be ready
    again (``wait_until_ready``) and the loop re-runs the trial; otherwise the session ends,
    finalised incomplete and resumable."""

    def __init__(self, reason: str, *, rerun: bool) -> None:
        super().__init__(reason)
        self.reason = reason
        self.rerun = rerun


class FrameRenderer(Protocol):
    """Renders one frame for a fixation; returns a check of the result.

    ``phase`` says what is shown (its ``name``: 'interval1', 'blank', ...; ``show``),
    ``mode`` the loop's rendering mode for it, ``t_in_phase_s`` the time since the phase began
    at the frame's display time, ``frame`` the display's request (views and targets).
    """

    def render(self, row: TrialRow, phase: PhaseSpec, mode: str, t_in_phase_s: float,
               fixation_m: tuple[float, float, float], head_pose: HeadPose | None = None,
               frame: FrameRequest | None = None) -> FrameCheck: ...

    def eye_textures(self) -> list[moderngl.Texture]: ...

    def close(self) -> None: ...


class Display(Protocol):
    """Where frames go (module docstring). ``name``: what session.json records as the display;
    ``gl_context``: the OpenGL context frames must be rendered in (None: the renderer makes its own);
    ``summary``: what the display measured, for session.json; ``paced``: True when
    ``begin_frame`` itself waits for the display's next frame slot (a headset runtime), so the loop
    never sleeps between frames."""

    name: str
    paced: bool

    @property
    def gl_context(self) -> moderngl.Context | None: ...

    def wait_until_ready(self) -> None: ...

    def begin_frame(self, not_before_s: float) -> FrameRequest: ...

    def end_frame(self, frame: FrameRequest, images: Sequence[moderngl.Texture]) -> float: ...

    def summary(self) -> JsonObject: ...

    def close(self) -> None: ...


class CameraRenderer:
    """Computes the cameras of the rig's eye(s) (psyop.optics.rig) for each frame; checks they
    are finite. This is the gaze-dependent part of every frame, without an image."""

    def __init__(self, display: DisplayProfile, rig: EyeRig) -> None:
        self.display, self.rig = display, rig

    def render(self, row: TrialRow, phase: PhaseSpec, mode: str, t_in_phase_s: float,
               fixation_m: tuple[float, float, float], head_pose: HeadPose | None = None,
               frame: FrameRequest | None = None) -> FrameCheck:
        ok = True  # cameras are in head space: the head pose changes no camera
        for eye in self.rig.eyes:
            view = frame.view(eye) if frame is not None else None
            camera = (self.rig.camera(self.display, eye, fixation_m, mode, row=row) if view is None
                      else self.rig.view_camera(view, self.display.width_px, self.display.height_px, fixation_m, mode,
                                                row=row))
            ok &= bool(np.isfinite(camera.view).all() and np.isfinite(camera.projection).all())
        return FrameCheck(False, ok)  # no image was made

    def eye_textures(self) -> list[moderngl.Texture]:
        return []

    def close(self) -> None:
        return None


def due_slot(asked_s: float, now_s: float, period_s: float) -> tuple[float, int]:
    """(display time, slots skipped) of the frame due at ``now_s`` on refresh slots ``asked_s + k * period_s``:
    the slot current at ``now_s`` (``asked_s`` itself while the clock is within its period).

    >>> due_slot(1.0, 1.005, 0.01)
    (1.0, 0)
    >>> due_slot(1.0, 1.0351, 0.01)
    (1.03, 3)
    """
    missed = max(0, math.floor((now_s - asked_s) / period_s))
    return (asked_s + missed * period_s if missed else asked_s), missed


class HeadlessDisplay:
    """No screen: the loop is paced by the session clock (a virtual clock jumps, a real one
    sleeps) and a frame is 'submitted' when the renderer returns.

    On a real clock its refresh slots are ``not_before_s + k * period``: a loop that asks late (the
    clock already past ``not_before_s + period``) gets the slot current at the clock's time, the ``k``
    slots skipped counted in ``missed_frames``. On a virtual clock every frame is on time."""

    name = "headless"
    paced = False

    def __init__(self, clock: Clock, refresh_hz: float) -> None:
        self._clock = clock
        self._period_s = 1.0 / float(refresh_hz)
        self._index = 0
        self.frames_missed = 0

    @property
    def gl_context(self) -> moderngl.Context | None:
        return None

    def wait_until_ready(self) -> None:
        return None

    def begin_frame(self, not_before_s: float) -> FrameRequest:
        self._clock.sleep_until(not_before_s)
        self._index += 1
        display_s, missed = float(not_before_s), 0
        if not self._clock.virtual:  # the slot due now (the clock may be far past the one asked for)
            display_s, missed = due_slot(display_s, self._clock.now_s(), self._period_s)
            self.frames_missed += missed
        return FrameRequest(self._index - 1, display_s, self._period_s, missed_frames=missed)

    def end_frame(self, frame: FrameRequest, images: Sequence[moderngl.Texture]) -> float:
        return self._clock.now_s()

    def summary(self) -> JsonObject:
        out: JsonObject = {"display": self.name, "frames": self._index}
        if not self._clock.virtual:
            out["frames_missed"] = self.frames_missed
        return out

    def close(self) -> None:
        return None


class FrameRecorder:
    """Collects one trial's frame rows column-wise; cheap to append, one batch per trial."""

    def __init__(self) -> None:
        # Any: FRAME_SCHEMA's column types. Built at the first frame: most trials of a sampled-regime
        # session (psyop power's) draw none, and a dict of ~50 lists per trial showed in its profile.
        self._cols: dict[str, list[Any]] | None = None
        self._n = 0

    def add(self, **values: Any) -> None:  # Any: one value per FRAME_SCHEMA column, of its type
        if self._cols is None:
            self._cols = {name: [] for name in FRAME_SCHEMA.names}
        for name, column in self._cols.items():
            column.append(values.get(name))
        self._n += 1

    def __len__(self) -> int:
        return self._n

    def table(self) -> pa.Table:
        cols = self._cols if self._cols is not None else {name: [] for name in FRAME_SCHEMA.names}
        return pa.Table.from_pydict(cols, schema=FRAME_SCHEMA)


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
