"""A real on-screen window (glfw) that presents the renderer's frames and logs their timing.

Headless EGL stays the default; this is for a desktop or an HMD's mirror window, and for the
frame-timing test under Xvfb. Xvfb has no vsync, so pacing comes from the caller's clock
(:func:`run_paced`), never from ``swap_interval``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from types import ModuleType
from typing import TYPE_CHECKING, Any, cast

import moderngl
import numpy as np

if TYPE_CHECKING:
    import glfw


class WindowUnavailable(RuntimeError):
    """No display/window system could be opened (reason in the message)."""


@dataclass(frozen=True)
class FrameTiming:
    """Per-frame presentation timestamps and the dropped-frame count against the refresh."""

    present_s: np.ndarray
    slot_start_s: np.ndarray
    refresh_interval_s: float
    dropped_frames: int
    late_frames: int


def count_dropped_frames(present_s: np.ndarray, refresh_interval_s: float) -> tuple[int, int]:
    """(dropped, late): a gap of k refresh intervals (rounded) between presentations drops
    k - 1 frames; ``late`` counts the gaps longer than 1.5 intervals."""
    gaps = np.diff(np.asarray(present_s, dtype=np.float64)) / refresh_interval_s
    late = int(np.sum(gaps > 1.5))
    dropped = int(np.sum(np.maximum(np.round(gaps) - 1.0, 0.0)))
    return dropped, late


BLIT_SHADER = """
#version 410 core
uniform sampler2D u_image;
uniform vec2 u_offset_px;
out vec4 colour;
void main() {
    ivec2 p = ivec2(gl_FragCoord.xy - u_offset_px);
    colour = vec4(clamp(texelFetch(u_image, p, 0).rgb, 0.0, 1.0), 1.0);
}
"""


class _GlfwLoader:
    """moderngl's GL function loader for a context glfw made current (glcontext cannot detect an EGL one)."""

    def __init__(self, glfw_module: ModuleType) -> None:
        self._glfw = glfw_module

    def load_opengl_function(self, name: str) -> int:
        return int(self._glfw.get_proc_address(name) or 0)

    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> None:
        return None

    def release(self) -> None:
        return None


class Window:
    """A glfw window with an OpenGL 4.1 core context wrapped by moderngl."""

    _window: glfw._GLFWwindowPointerT | None  # None once released
    _blit: tuple[moderngl.Program, moderngl.VertexArray] | None  # set by the first present_side_by_side

    def __init__(self, width_px: int, height_px: int, title: str = "psyop", swap_interval: int = 1, *,
                 egl: bool = False):
        """``egl``: the window's context is made through EGL (on X11 too) rather than the platform's own API
        (GLX), so that it can take turns on one thread with other EGL contexts (an OpenXR session's); its GL
        functions are then loaded through glfw."""
        import glfw  # imported here: headless use never needs it

        self._glfw = glfw
        if not glfw.init():
            raise WindowUnavailable("glfw.init() failed (no X display? run under xvfb-run)")
        glfw.default_window_hints()
        if egl:
            glfw.window_hint(glfw.CONTEXT_CREATION_API, glfw.EGL_CONTEXT_API)
        glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 4)
        glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 1)
        glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
        glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
        glfw.window_hint(glfw.RESIZABLE, False)
        self._window = glfw.create_window(width_px, height_px, title, None, None)
        if not self._window:
            glfw.terminate()
            raise WindowUnavailable("glfw.create_window failed")
        glfw.make_context_current(self._window)
        glfw.swap_interval(swap_interval)
        try:
            loader = cast(Any, _GlfwLoader(glfw))  # Any: moderngl's stub says dict; it takes any loader object
            self.ctx = moderngl.create_context(context=loader) if egl else moderngl.create_context()
        except Exception as exc:  # re-raised as WindowUnavailable: no usable OpenGL 4.1 context here
            glfw.destroy_window(self._window)
            glfw.terminate()
            raise WindowUnavailable(f"no OpenGL context for the window: {exc}") from exc
        self.width_px, self.height_px = width_px, height_px

    def make_current(self) -> None:
        """Make the window's context current on this thread (after another context was)."""
        self._glfw.make_context_current(self.handle)

    @property
    def handle(self) -> glfw._GLFWwindowPointerT:
        """The live glfw window (for key callbacks and flips by the display that owns this window)."""
        assert self._window is not None, "window used after release"
        return self._window

    def present(self, framebuffer: moderngl.Framebuffer) -> None:
        """Copy a framebuffer of the window's size to the screen and swap."""
        self.ctx.copy_framebuffer(self.ctx.screen, framebuffer)
        assert self._window is not None, "present after release"
        self._glfw.swap_buffers(self._window)
        self._glfw.poll_events()

    def present_side_by_side(self, textures: list[moderngl.Texture]) -> None:
        """Show colour textures left to right (e.g. the left and right eye, each at full
        render resolution: texel = screen pixel), then swap. The window must be wide enough."""
        from psyop.rendering.shaders import VERTEX_SHADER

        blit = getattr(self, "_blit", None)
        if blit is None:
            prog = self.ctx.program(vertex_shader=VERTEX_SHADER, fragment_shader=BLIT_SHADER)
            blit = self._blit = (prog, self.ctx.vertex_array(prog, []))
        prog, vao = blit
        self.ctx.screen.use()
        x = 0
        for texture in textures:
            width, height = texture.size
            self.ctx.viewport = (x, 0, width, height)
            texture.use(0)
            cast(moderngl.Uniform, prog["u_image"]).value = 0  # BLIT_SHADER declares both as uniforms
            cast(moderngl.Uniform, prog["u_offset_px"]).value = (float(x), 0.0)
            vao.render(moderngl.TRIANGLES, vertices=3)
            x += width
        self.ctx.viewport = (0, 0, self.width_px, self.height_px)
        assert self._window is not None, "present after release"
        self._glfw.swap_buffers(self._window)
        self._glfw.poll_events()

    def screen_pixels(self) -> np.ndarray:
        """(H, W, 3) uint8 of the back buffer's current content, top row first."""
        raw = self.ctx.screen.read(components=3, dtype="f1")
        return np.frombuffer(raw, dtype=np.uint8).reshape(self.height_px, self.width_px, 3)[::-1]

    def release(self) -> None:
        if self._window is not None:
            for obj in reversed(getattr(self, "_blit", None) or ()):
                obj.release()
            self._blit = None
            self.ctx.release()
            self._glfw.destroy_window(self._window)
            self._glfw.terminate()
            self._window = None

    def __enter__(self) -> Window:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def run_paced(
    n_frames: int,
    refresh_interval_s: float,
    draw_and_present: Callable[[int], None],
    clock: Callable[[], float] = time.perf_counter,
    sleep: Callable[[float], None] = time.sleep,
) -> FrameTiming:
    """Call ``draw_and_present(k)`` once per refresh slot, paced by ``clock``, timestamping
    each presentation. A frame that finishes after its slot makes the next one wait for the
    following free slot, which is what a vsynced display does, so the gaps expose drops."""
    start = clock()
    stamps = np.empty(n_frames)
    slots = np.empty(n_frames)
    slot = 0
    for k in range(n_frames):
        deadline = start + slot * refresh_interval_s
        slots[k] = deadline
        wait = deadline - clock()
        if wait > 0:
            sleep(wait)
        draw_and_present(k)
        stamps[k] = clock()
        slot = max(slot + 1, int(np.ceil((stamps[k] - start) / refresh_interval_s)))
    dropped, late = count_dropped_frames(stamps, refresh_interval_s)
    return FrameTiming(stamps, slots, refresh_interval_s, dropped, late)
