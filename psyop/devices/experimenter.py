"""The experimenter's window (``psyop run --experimenter-window``): a small glfw window on the experimenter's
screen while a session runs on a headset (or headless), showing

- a mirror of what the participant sees: one eye's image (``--mirror-eye left``, the default, or ``right``: that
  eye's swapchain image on a headset) or both side by side (``both``, left eye on the left), each downscaled on the
  GPU to ``--mirror-width-px`` (default :data:`MIRROR_WIDTH_PX`) and shown about :data:`MIRROR_HZ` times a second;
- a status strip: trial k of N and its condition, the phase, the last answer, the display's dropped frames so
  far and the share of frames whose gaze sample was valid (``status_line``; ``status_updates`` counts changes).

Its keys are a :class:`~psyop.devices.responses.keyboard.KeyEvents` source: ``--responses keyboard`` reads them
(the experimenter keys in the participant's spoken answers, or the participant uses a keyboard). Escape ends the
session as Ctrl-C does (exit 130, resumable), as in the session window; ``p`` (pause) and ``c`` (recalibrate) go to
the session's controls (psyop.session.controls), never to the answers.

How it hooks in, through the session's seams (the loop never sees it): :class:`MirroredDisplay` wraps the
session's display (each frame passes through it; the display itself is unchanged), the window is an
:class:`~psyop.session.events.EventSink` (trial starts, phases, answers) and :class:`WatchedGaze` wraps the
gaze source, counting the valid samples the loop is handed.

Cost (measured per update, in ``summary()``, session.json ``summary.display.experimenter_window``): before the
frame is submitted only the downscale draw is queued (no wait: ``queue_ms``); after ``xrEndFrame`` (the frame's
images are complete by then: the display waited for them) the small image is read back (about 0.3 MB), the
window's context is made current, the image drawn and swapped without waiting for the screen's refresh
(swap interval 0), and the display's context made current again (``present_ms``). That second part runs in the
time the loop would otherwise wait in ``xrWaitFrame``; it delays no submitted frame unless it outgrows that slack.

Contexts: the window's context is made through EGL when the display's is (``egl``: the EGL binding, the headless
renderer), through the platform's API (GLX) otherwise, so both take turns on the loop's thread; after every use
of its own the window makes the display's context current again.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from psyop.session.controls import ESCAPE_KEY, EscapePressed, SessionControls
from psyop.session.events import SessionEvent
from psyop.session.frames import Display, FrameRequest
from psyop.session.gaze.sample import GazeSample, GazeSource
from psyop.session.rows import JsonObject

if TYPE_CHECKING:
    import moderngl

    from psyop.session.clock import Clock

#: the mirror's width in the window (pixels); its height follows the eye image's aspect ratio
MIRROR_WIDTH_PX = 320
#: the status strip below the mirror (pixels)
STATUS_HEIGHT_PX = 36
#: mirror updates per second (at most one per frame): a monitor for the experimenter, not a second display
MIRROR_HZ = 15.0

DOWNSCALE_SHADER = """
#version 330 core
uniform sampler2D u_image;
uniform ivec2 u_src;
uniform ivec2 u_dst;
uniform int u_offset;
out vec4 colour;
void main() {
    vec2 step = vec2(u_src) / vec2(u_dst);
    vec2 base = (floor(gl_FragCoord.xy) - vec2(float(u_offset), 0.0)) * step;
    vec3 sum = vec3(0.0);
    for (int j = 0; j < 4; ++j) {
        for (int i = 0; i < 4; ++i) {
            ivec2 p = ivec2(base + (vec2(i, j) + 0.5) * step / 4.0);
            sum += texelFetch(u_image, clamp(p, ivec2(0), u_src - 1), 0).rgb;
        }
    }
    colour = vec4(clamp(sum / 16.0, 0.0, 1.0), 1.0);
}
"""

FULLSCREEN_VERTEX = """
#version 330 core
void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""


class ExperimenterWindow:
    """The window (module docstring): a KeyEvents source, an EventSink, and the mirror's screen.

    ``n_trials``: the schedule's length (the status's N); ``mirror_px``: (width, height) of one eye's mirror;
    ``eyes``: the eyes mirrored, side by side in this order (``mirror_px`` holds all of them);
    ``egl``: make the window's context through EGL (module docstring); ``controls``: where Escape, ``p`` and ``c``
    go (psyop.session.controls; None: Escape alone, raised from :meth:`pump`)."""

    def __init__(self, clock: Clock, n_trials: int, mirror_px: tuple[int, int], *, egl: bool,
                 restore: moderngl.Context | None = None, controls: SessionControls | None = None,
                 eyes: Sequence[str] = ("left",)) -> None:
        from psyop.errors import UserError
        from psyop.rendering.window import Window, WindowUnavailable

        self.eyes = tuple(eyes)
        self.eye_px = (int(mirror_px[0]), int(mirror_px[1]))
        self.mirror_px = (self.eye_px[0] * len(self.eyes), self.eye_px[1])
        width, height = self.mirror_px[0], self.mirror_px[1] + STATUS_HEIGHT_PX
        try:
            self._window = Window(width, height, title="psyop: experimenter", swap_interval=0, egl=egl)
        except WindowUnavailable as exc:
            raise UserError(f"cannot open the experimenter window: {exc}", "--experimenter-window") from exc
        import glfw

        self._glfw = glfw
        self._clock = clock
        self._restore = restore  # the context current before the window's (made current again after each use)
        self._keys: list[tuple[str, float]] = []
        self.escape_pressed = False
        self.controls = controls
        if controls is not None:
            controls.pumps.append(self.pump)
        glfw.set_key_callback(self._window.handle, self._on_key)
        ctx = self._window.ctx
        self._texture = ctx.texture((width, height), 3, dtype="f1")
        self._program = ctx.program(vertex_shader=FULLSCREEN_VERTEX, fragment_shader="""
#version 330 core
uniform sampler2D u_image;
out vec4 colour;
void main() { colour = vec4(texelFetch(u_image, ivec2(gl_FragCoord.xy), 0).rgb, 1.0); }
""")
        self._vao = ctx.vertex_array(self._program, [])
        self._image = np.full((height, width, 3), 40, dtype=np.uint8)  # the window's content, top row first
        self._mirror_seen = False
        self._reset_status(n_trials)
        self._draw_status()
        self._present()

    def _reset_status(self, n_trials: int) -> None:
        self.n_trials = int(n_trials)
        self.trial = -1
        self.condition = ""
        self.phase = ""
        self.last_answer = ""
        self.recorded = 0
        self.dropped_frames = 0
        self.gaze_valid = 0
        self.gaze_total = 0
        self.status_line = ""
        self.status_updates = 0
        self._status_drawn = ""
        self._font: Any = None  # Any: PIL's ImageFont (loaded on first use)

    # -- keys (KeyEvents) -------------------------------------------------------------------------------
    def _on_key(self, window: object, key: int, scancode: int, action: int, mods: int) -> None:
        if action != self._glfw.PRESS:
            return
        from psyop.devices.window import key_name

        name = key_name(self._glfw, key, scancode)
        if name == ESCAPE_KEY:  # noted only: an exception raised in a glfw callback is lost in ctypes
            self.escape_pressed = True
            return
        if self.controls is not None and self.controls.press(name, "the experimenter window"):
            return
        self._keys.append((name, self._clock.now_s()))

    def pump(self) -> None:
        """Deliver the window system's pending events; Escape ends the session (as Ctrl-C)."""
        self._glfw.poll_events()
        if self.escape_pressed:
            if self.controls is not None:
                self.controls.press(ESCAPE_KEY, "the experimenter window")
            raise EscapePressed("Escape pressed in the experimenter window")

    def inject_key(self, name: str) -> None:
        """Queue a key press as if typed (tests, scripted demos)."""
        self._keys.append((name, self._clock.now_s()))

    def poll(self) -> list[tuple[str, float]]:
        self.pump()
        keys, self._keys = self._keys, []
        return keys

    # -- status (EventSink and the display/gaze wrappers) -------------------------------------------------
    def emit(self, event: SessionEvent) -> None:
        if event.kind == "trial_start":
            self.trial, self.condition, self.phase = event.trial, event.condition, ""
        elif event.kind == "phase":
            self.phase = event.value
            if event.trial < 0:
                self.trial, self.condition = event.trial, event.condition
        elif event.kind == "response":
            self.last_answer = event.value
        elif event.kind == "trial_end":
            self.recorded += 1

    def status(self) -> str:
        """The status as one line (what the strip shows, on two)."""
        if self.trial >= 0:
            where = f"trial {self.trial + 1} of {self.n_trials} | condition {self.condition or '-'}"
        elif self.condition:
            where = f"{self.condition.replace('_', ' ')} | {self.n_trials} trials"
        else:
            where = f"waiting | {self.n_trials} trials"
        share = f"{100.0 * self.gaze_valid / self.gaze_total:.0f}%" if self.gaze_total else "-"
        return (f"{where} | phase {self.phase or '-'} | last answer {self.last_answer or '-'} | "
                f"recorded {self.recorded} | dropped frames {self.dropped_frames} | gaze valid {share}")

    def _draw_status(self) -> None:
        line = self.status()
        self.status_line = line
        if line == self._status_drawn:
            return
        from PIL import Image, ImageDraw, ImageFont

        if self._font is None:
            self._font = ImageFont.load_default(size=11)
        width = self._image.shape[1]
        strip = Image.new("RGB", (width, STATUS_HEIGHT_PX), (24, 24, 24))
        draw = ImageDraw.Draw(strip)
        parts = line.split(" | ")
        half = 3 if len(parts) > 4 else len(parts)
        for row, text in enumerate((" | ".join(parts[:half]), " | ".join(parts[half:]))):
            draw.text((4, 3 + 16 * row), text, fill=(230, 230, 230), font=self._font)
        self._image[self.mirror_px[1]:] = np.asarray(strip, dtype=np.uint8)
        self._status_drawn = line
        self.status_updates += 1

    # -- the mirror ---------------------------------------------------------------------------------------
    def show_mirror(self, pixels: np.ndarray | None) -> None:
        """Show ``pixels`` ((h, w, 3) uint8, bottom row first as GL reads it) and the status; swap."""
        if pixels is not None:
            h, w = self.mirror_px[1], self.mirror_px[0]
            self._image[:h] = pixels[::-1, :w]
            self._mirror_seen = True
        self._draw_status()
        self._present()

    def _present(self) -> None:
        self._window.make_current()
        try:
            ctx = self._window.ctx
            self._texture.write(np.ascontiguousarray(self._image[::-1]).tobytes())
            ctx.screen.use()
            ctx.viewport = (0, 0, self._image.shape[1], self._image.shape[0])
            self._texture.use(0)
            self._vao.render(vertices=3)
            self._glfw.swap_buffers(self._window.handle)
        finally:
            self.restore()

    def restore_to(self, ctx: moderngl.Context) -> None:
        """The context to make current after each use of the window's own (the display's, or the renderer's)."""
        self._restore = ctx

    def restore(self) -> None:
        """Make the context that was current before the window's current again (the display's)."""
        if self._restore is not None:
            self._restore.__enter__()
        else:
            self._glfw.make_context_current(None)  # type: ignore[arg-type]  # glfw takes None: no context current

    def screen_pixels(self) -> np.ndarray:
        """(H, W, 3) uint8 of what the window shows now (the last presented image), top row first."""
        self._window.make_current()
        try:
            self._present_back()
            return self._window.screen_pixels()
        finally:
            self.restore()

    def _present_back(self) -> None:
        """Draw the current image into the back buffer again (a swap leaves it undefined), without swapping."""
        ctx = self._window.ctx
        ctx.screen.use()
        self._texture.use(0)
        self._vao.render(vertices=3)

    def close(self) -> None:
        if getattr(self, "_window", None) is None:
            return
        window, self._window = self._window, None  # type: ignore[assignment]  # closed: never used again
        window.make_current()
        try:
            for obj in (self._vao, self._program, self._texture):
                obj.release()
        finally:
            window.release()
            if self._restore is not None:
                self._restore.__enter__()


class MirroredDisplay:
    """The session's display with the experimenter window's mirror: every call goes to ``inner``; a frame's
    first eye image is queued for the mirror before it is submitted and shown after (module docstring)."""

    def __init__(self, inner: Display, window: ExperimenterWindow) -> None:
        self.inner = inner
        self.window = window
        self.name = inner.name
        self.paced = inner.paced
        self._every = 1
        self._n = 0
        self._frames_since = 0
        self._programs: dict[int, tuple[Any, Any, Any]] = {}  # Any: moderngl objects of one source context
        self._pending: tuple[Any, Any] | None = None  # Any: (the small framebuffer, its context) queued this frame
        self.updates = 0
        self.queue_s: list[float] = []
        self.present_s: list[float] = []

    @property
    def gl_context(self) -> moderngl.Context | None:
        return self.inner.gl_context

    def wait_until_ready(self) -> None:
        self.inner.wait_until_ready()

    def begin_frame(self, not_before_s: float) -> FrameRequest:
        self.window.pump()
        request = self.inner.begin_frame(not_before_s)
        self.window.dropped_frames += request.missed_frames
        if request.period_s > 0:
            self._every = max(1, int(round(1.0 / (request.period_s * MIRROR_HZ))))
        return request

    def end_frame(self, frame: FrameRequest, images: Sequence[moderngl.Texture]) -> float:
        self._frames_since += 1
        due = self._frames_since >= self._every
        if due:
            started = time.perf_counter()
            self._pending = self._queue_downscale(frame, images)
            self.queue_s.append(time.perf_counter() - started)
        submit_s = self.inner.end_frame(frame, images)
        if due:
            started = time.perf_counter()
            self._frames_since = 0
            pixels = None
            if self._pending is not None:
                small, ctx = self._pending
                self._pending = None
                raw = small.read(components=3, dtype="f1")
                w, h = small.size
                pixels = np.frombuffer(raw, dtype=np.uint8).reshape(h, w, 3)
                self.window.restore_to(ctx)  # the context the mirror's source lives in (current again after)
            self.window.show_mirror(pixels)
            self.updates += 1
            self.present_s.append(time.perf_counter() - started)
        return submit_s

    def _sources(self, frame: FrameRequest, images: Sequence[moderngl.Texture]) -> list[tuple[Any, tuple[int, int]]]:
        """Each mirrored eye's image and its size (Any: a moderngl texture): the eye's swapchain image on a
        headset, else the renderer's image of that eye (the left one first; a single image serves every eye)."""
        out: list[tuple[Any, tuple[int, int]]] = []
        for i, eye in enumerate(self.window.eyes):
            if frame.targets:
                target = frame.targets.get(eye) or next(iter(frame.targets.values()))
                texture = cast("moderngl.Texture", target.framebuffer.color_attachments[0])  # a swapchain image
                out.append((texture, (target.width_px, target.height_px)))
            elif images:
                image = images[min(i if len(self.window.eyes) > 1 else int(eye == "right"), len(images) - 1)]
                out.append((image, (int(image.size[0]), int(image.size[1]))))
        return out

    def _queue_downscale(self, frame: FrameRequest, images: Sequence[moderngl.Texture]) -> tuple[Any, Any] | None:
        """Draw each mirrored eye's image, downscaled, side by side into a small framebuffer of its own context
        (queued, no wait)."""
        sources = self._sources(frame, images)
        if not sources:
            return None
        ctx = sources[0][0].ctx
        cached = self._programs.get(id(ctx))
        if cached is None:
            program = ctx.program(vertex_shader=FULLSCREEN_VERTEX, fragment_shader=DOWNSCALE_SHADER)
            small = ctx.simple_framebuffer(self.window.mirror_px, components=4)
            cached = self._programs[id(ctx)] = (program, ctx.vertex_array(program, []), small)
        program, vao, small = cached
        previous = ctx.fbo
        small.use()
        width, height = self.window.eye_px
        for i, (source, size) in enumerate(sources):
            ctx.viewport = (i * width, 0, width, height)
            source.use(0)
            for name, value in (("u_image", 0), ("u_src", size), ("u_dst", (width, height)), ("u_offset", i * width)):
                cast("moderngl.Uniform", program[name]).value = value  # DOWNSCALE_SHADER declares them as uniforms
            vao.render(vertices=3)
        if previous is not None:  # the framebuffer bound before (None before anything was drawn: cameras only)
            previous.use()
        return small, ctx

    def summary(self) -> JsonObject:
        out = dict(self.inner.summary())
        out["experimenter_window"] = self.cost()
        return out

    def cost(self) -> JsonObject:
        """What the mirror cost (per update, ms): the draw queued before submitting, the read-back and present after."""
        def stats(values: list[float]) -> JsonObject:
            if not values:
                return {"median_ms": None, "p95_ms": None, "max_ms": None}
            ms = np.asarray(values) * 1e3
            return {"median_ms": float(np.median(ms)), "p95_ms": float(np.percentile(ms, 95)), "max_ms": float(ms.max())}

        return {"mirror_px": list(self.window.mirror_px), "mirror_eyes": list(self.window.eyes),
                "mirror_every_frames": self._every,
                "mirror_updates": self.updates, "queue_before_submit": stats(self.queue_s),
                "readback_and_present_after_submit": stats(self.present_s), "status_updates": self.window.status_updates,
                "status": self.window.status_line}

    def close(self) -> None:
        """Release the mirror's objects in the display's contexts (the display itself is closed by its owner)."""
        for program, vao, small in self._programs.values():
            for obj in (vao, program, small):
                try:
                    obj.release()
                except Exception:  # noqa: BLE001 - teardown goes on
                    pass
        self._programs = {}


class WatchedGaze:
    """A gaze source as given, counting the samples the loop is handed and how many were valid (the status)."""

    def __init__(self, inner: GazeSource, window: ExperimenterWindow) -> None:
        self.inner = inner
        self.window = window

    def start(self) -> None:
        self.inner.start()

    def latest(self, now_s: float) -> GazeSample | None:
        sample = self.inner.latest(now_s)
        self.window.gaze_total += 1
        if sample is not None and sample.valid and all(math.isfinite(v) for v in sample.fixation_m):
            self.window.gaze_valid += 1
        return sample

    def __getattr__(self, name: str) -> Any:  # Any: every other member of the wrapped source, as it is
        return getattr(self.inner, name)

    def set_plan(self, plan: Any) -> None:  # Any: the source's FixationPlan, passed on
        self.inner.set_plan(plan)

    def clock_sync(self) -> Any:  # Any: the source's ClockSync or None, passed on
        return self.inner.clock_sync()

    def drain_raw(self) -> Any:  # Any: the source's raw samples, passed on
        return self.inner.drain_raw()

    def stats(self) -> dict[str, float | int]:
        return self.inner.stats()

    def close(self) -> None:
        self.inner.close()


__all__ = ["ExperimenterWindow", "MIRROR_HZ", "MIRROR_WIDTH_PX", "MirroredDisplay", "WatchedGaze"]
