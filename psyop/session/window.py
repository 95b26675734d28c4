"""A real window for sessions (``--display window``): presents frames, delivers key presses.

Built on :class:`psyop.rendering.window.Window` (glfw + moderngl). With a
:class:`~psyop.session.scene_renderer.SceneRenderer` sharing the window's context
(``source``), each submit presents the newest image of every eye, side by side for a
stereo protocol (left eye on the left), at the render resolution: ``scale`` 1
(``psyop run --window-scale 1``) shows the display profile's full resolution per eye.
Before any image (and when there is no source) the screen is flat grey. Flip times are recorded on the real clock
(:meth:`RealClock.on_flip`), which estimates the display's refresh period.
"""

from __future__ import annotations

from typing import Any


class GlfwWindow:
    """Implements the loop's Display and the keyboard's KeyEvents."""

    def __init__(self, display_profile: Any, clock: Any, *, scale: float = 0.25, n_eyes: int = 1) -> None:
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
        """Present every eye's newest image side by side (flat grey before any) and flip."""
        ctx = self._window.ctx
        textures = self.source.eye_textures() if self.source is not None else []
        if textures and sum(t.size[0] for t in textures) <= self._window.width_px:
            self._window.present_side_by_side(textures)
        else:
            ctx.screen.use()
            ctx.clear(self.shade, self.shade, self.shade)
            self._glfw.swap_buffers(self._window._window)
        on_flip = getattr(self._clock, "on_flip", None)
        return on_flip() if on_flip is not None else self._clock.now_s()

    def close(self) -> None:
        self._window.release()
