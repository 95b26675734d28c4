"""A real window for sessions (``--display window``): presents frames, delivers key presses.

Built on :class:`psyop.rendering.window.Window` (glfw + moderngl). With a
:class:`~psyop.session.scene_renderer.SceneRenderer` sharing the window's context
(``source``), each submit presents the newest rendered eye image; outside stimulus phases
(cross, blank, prompt) the screen is flat grey. Flip times are recorded on the real clock
(:meth:`RealClock.on_flip`), which estimates the display's refresh period.
"""

from __future__ import annotations

from typing import Any


class GlfwWindow:
    """Implements the loop's Display and the keyboard's KeyEvents."""

    def __init__(self, display_profile: Any, clock: Any, *, scale: float = 0.25) -> None:
        from psyop.errors import UserError
        from psyop.rendering.window import Window, WindowUnavailable

        try:
            self._window = Window(max(64, int(display_profile.width_px * scale)),
                                  max(64, int(display_profile.height_px * scale)), title="psyop session")
        except WindowUnavailable as exc:
            raise UserError(f"cannot open a window: {exc}", "--display") from exc
        import glfw

        self._glfw = glfw
        self._clock = clock
        self._keys: list[tuple[str, float]] = []
        glfw.set_key_callback(self._window._window, self._on_key)
        self.shade = 0.5
        self.scale = scale
        self.source: Any = None  # a SceneRenderer sharing this window's context
        self._presented: Any = None

    @property
    def ctx(self) -> Any:
        return self._window.ctx

    def _on_key(self, window: Any, key: int, scancode: int, action: int, mods: int) -> None:
        if action != self._glfw.PRESS:
            return
        name = self._glfw.get_key_name(key, scancode)
        if name is None:
            name = {self._glfw.KEY_LEFT: "left", self._glfw.KEY_RIGHT: "right", self._glfw.KEY_SPACE: "space",
                    self._glfw.KEY_ENTER: "enter", self._glfw.KEY_KP_1: "kp_1", self._glfw.KEY_KP_2: "kp_2",
                    self._glfw.KEY_ESCAPE: "escape"}.get(key, "")
        self._keys.append((name, self._clock.now_s()))
        if name == "escape":
            raise KeyboardInterrupt  # ends the session cleanly (the trial in progress is discarded)

    def inject_key(self, name: str) -> None:
        """Queue a key press as if typed (for tests and scripted demos)."""
        self._keys.append((name, self._clock.now_s()))

    def poll(self) -> list[tuple[str, float]]:
        self._glfw.poll_events()
        keys, self._keys = self._keys, []
        return keys

    def submit(self) -> float:
        """Present the renderer's newest image (or a flat grey screen outside stimuli) and flip."""
        ctx = self._window.ctx
        framebuffer = self.source.last_framebuffer() if self.source is not None else None
        if framebuffer is not None and framebuffer.size == (self._window.width_px, self._window.height_px):
            self._window.present(framebuffer)
        else:
            ctx.screen.use()
            ctx.clear(self.shade, self.shade, self.shade)
            self._glfw.swap_buffers(self._window._window)
        on_flip = getattr(self._clock, "on_flip", None)
        return on_flip() if on_flip is not None else self._clock.now_s()

    def close(self) -> None:
        self._window.release()
