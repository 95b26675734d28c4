"""A real window for sessions (``--display window``): presents frames, delivers key presses.

Built on :class:`psyop.rendering.window.Window` (glfw + moderngl). It implements the loop's
:class:`~psyop.session.frames.Display`: frames are rendered in the window's own OpenGL context
(``gl_context``), and each ``end_frame`` presents the eye images it is given, side by side for a
stereo protocol (left eye on the left), at the render resolution: ``scale`` 1
(``psyop run --window-scale 1``) shows the display profile's full resolution per eye. Before any
image the screen is flat grey. Flip times are recorded (:class:`~psyop.session.clock.FlipSync`),
which estimates the display's refresh period for session.json.

On a real clock the window hands out the frame due when it is asked (as the headless display does:
:func:`psyop.session.frames.due_slot`): a loop that comes late, because the last frame's rendering or
its flip (a swap that waited for a later vertical blank) took longer than a period, gets the refresh
slot current at the clock's time, and the slots it skipped are counted (``missed_frames``); the flip
timestamps give ``display_flip_period_s`` and the flips that came more than half a period after
their frame's slot ended (``flips_late``).

Escape ends the session as Ctrl-C does (exit 130, the trial in progress discarded, the session
resumable): the key callback, which glfw calls from C through ctypes (an exception raised there is
printed and dropped), only notes the press; the window raises :class:`EscapePressed` (a
KeyboardInterrupt) from the next ``begin_frame`` or ``poll``, in the loop's own Python frames, where
Ctrl-C would have arrived. Events are pumped at every frame, so Escape works in every phase. The
other control keys (``p`` pause, ``c`` recalibrate: psyop.session.controls) go to the session's
:class:`~psyop.session.controls.SessionControls` when it is given, never to the key queue.
"""

from __future__ import annotations

from collections.abc import Sequence
from types import ModuleType
from typing import TYPE_CHECKING

from psyop.session.rows import JsonObject
from psyop.session.clock import FlipSync
from psyop.session.controls import ESCAPE_KEY, EscapePressed, SessionControls
from psyop.session.frames import FrameRequest, due_slot

__all__ = ["EscapePressed", "GlfwWindow", "key_name"]

if TYPE_CHECKING:
    import moderngl

    from psyop.optics.display import DisplayProfile
    from psyop.session.clock import Clock


def key_name(glfw: ModuleType, key: int, scancode: int) -> str:
    """The name a key press is queued under: the layout's printable name (``2``, ``a``), else one of the named
    keys (``left``, ``space``, ``enter``, ``escape``, ...), else empty."""
    name = glfw.get_key_name(key, scancode)
    if name is None:
        name = {glfw.KEY_LEFT: "left", glfw.KEY_RIGHT: "right", glfw.KEY_SPACE: "space",
                glfw.KEY_ENTER: "enter", glfw.KEY_KP_1: "kp_1", glfw.KEY_KP_2: "kp_2",
                glfw.KEY_ESCAPE: "escape", glfw.KEY_UP: "up", glfw.KEY_DOWN: "down",
                glfw.KEY_KP_ENTER: "kp_enter"}.get(key, "")
    return str(name)


class GlfwWindow:
    """Implements the loop's Display and the keyboard's KeyEvents."""

    name = "window"
    paced = False

    def __init__(self, display_profile: DisplayProfile, clock: Clock, *, scale: float = 0.25, n_eyes: int = 1,
                 controls: SessionControls | None = None) -> None:
        from psyop.errors import UserError
        from psyop.rendering.window import Window, WindowUnavailable

        if not (0.0 < scale <= 1.0):
            raise UserError(f"window scale must be in (0, 1] (1 = the display's full resolution), got {scale:g}",
                            "--window-scale")
        self.n_eyes = n_eyes
        try:
            self._window = Window(max(64, n_eyes * max(16, round(display_profile.width_px * scale))),
                                  max(64, max(16, round(display_profile.height_px * scale))), title="psyop session")
        except WindowUnavailable as exc:
            raise UserError(f"cannot open a window: {exc}", "--display") from exc
        import glfw

        self._glfw = glfw
        self._clock = clock
        self._period_s = 1.0 / float(display_profile.refresh_hz)
        self._keys: list[tuple[str, float]] = []
        self.escape_pressed = False  # set by the key callback; acted on by pump (never raised from a callback)
        self.controls = controls
        if controls is not None:
            controls.pumps.append(self.pump)
        glfw.set_key_callback(self._window.handle, self._on_key)
        self.shade = 0.5
        self.scale = scale
        self.flips = FlipSync()
        self._index = 0
        self.frames_missed = 0  # slots skipped (real clock): the sum of every frame's missed_frames
        self.flips_late = 0  # flips more than half a period after the display time they were drawn for

    @property
    def gl_context(self) -> moderngl.Context | None:
        return self._window.ctx

    @property
    def ctx(self) -> moderngl.Context:
        return self._window.ctx

    def _on_key(self, window: object, key: int, scancode: int, action: int, mods: int) -> None:
        if action != self._glfw.PRESS:
            return
        name = key_name(self._glfw, key, scancode)
        if name == ESCAPE_KEY:  # noted only: an exception raised here would be lost in ctypes (module docstring)
            self.escape_pressed = True
            return
        if self.controls is not None and self.controls.press(name, "the session window"):
            return
        self._keys.append((name, self._clock.now_s()))

    def pump(self) -> None:
        """Deliver the window system's pending events (key presses into the queue); Escape ends the session."""
        self._glfw.poll_events()
        if self.escape_pressed:
            if self.controls is not None:
                self.controls.press(ESCAPE_KEY, "the session window")
            raise EscapePressed("Escape pressed in the session window")

    def inject_key(self, name: str) -> None:
        """Queue a key press as if typed (for tests and scripted demos)."""
        self._keys.append((name, self._clock.now_s()))

    def poll(self) -> list[tuple[str, float]]:
        self.pump()
        keys, self._keys = self._keys, []
        return keys

    def wait_until_ready(self) -> None:
        return None

    def begin_frame(self, not_before_s: float) -> FrameRequest:
        """Wait on the session clock until ``not_before_s``. Real clock: the frame due now (module
        docstring); virtual clock: the frame is shown at the next flip (predicted from the flips so far
        once there are enough of them). Escape pressed since the last frame ends the session here."""
        self.pump()
        self._clock.sleep_until(not_before_s)
        self._index += 1
        if not self._clock.virtual:
            shown_s, missed = due_slot(float(not_before_s), self._clock.now_s(), self._period_s)
            self.frames_missed += missed
            return FrameRequest(self._index - 1, shown_s, self._period_s, missed_frames=missed)
        shown_s = float(not_before_s)
        if len(self.flips.times_s) >= 8:
            shown_s = max(shown_s, self.flips.next_flip_s(self._clock.now_s(), self._period_s))
        return FrameRequest(self._index - 1, shown_s, self._period_s)

    def end_frame(self, frame: FrameRequest, images: Sequence[moderngl.Texture]) -> float:
        """Present every eye's newest image side by side (flat grey before any) and flip; the flip time."""
        ctx = self._window.ctx
        if images and sum(t.size[0] for t in images) <= self._window.width_px:
            self._window.present_side_by_side(list(images))
        else:
            ctx.screen.use()
            ctx.clear(self.shade, self.shade, self.shade)
            self._glfw.swap_buffers(self._window.handle)
        t_s = self._clock.now_s()
        self.flips.add(t_s)
        if t_s > frame.display_time_s + frame.period_s * 1.5:  # shown after the slot following its own
            self.flips_late += 1
        return t_s

    def framebuffer_size_px(self) -> tuple[int, int]:
        """The window's framebuffer as the window system made it (pixels; it may differ from the size asked for)."""
        width, height = self._glfw.get_framebuffer_size(self._window.handle)
        return int(width), int(height)

    def summary(self) -> JsonObject:
        out: JsonObject = {"display": self.name, "frames": self._index, "frames_missed": self.frames_missed,
                           "flips_late": self.flips_late}
        if len(self.flips.times_s) >= 8:  # from the flip timestamps (least squares)
            out["display_flip_period_s"] = self.flips.estimate(self._period_s)[0]
        return out

    def close(self) -> None:
        self._window.release()
