"""The full-field patches ``psyop calibrate`` shows, and the order it shows them in.

- ``--display headless``: an offscreen framebuffer in a headless EGL context
  (:func:`psyop.rendering.renderer.create_headless_context`), cleared to the patch's colour and read back, so the
  patch is what the GL pipeline made of the code, not only what was asked for. Nothing reaches a screen: this is
  for tests and for a photometer emulator;
- ``--display window``: a glfw window (the ``window`` extra), full screen on the primary monitor by default,
  cleared to the patch and swapped (twice, so both buffers hold it), its front pixels read back the same way;
  the patch then stays up ``settle_s`` (the display's response) before the photometer is read.

With ``--patch-log FILE`` each patch, as read back, is appended to FILE as one JSON line ``{"rgb": [r, g, b]}``
(8-bit codes) and flushed before the photometer is asked, so an emulated photometer on a pty sees the screen.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from psyop.errors import UserError

if TYPE_CHECKING:
    import moderngl

Rgb = tuple[int, int, int]

CHANNEL_MASKS: dict[str, Rgb] = {"grey": (1, 1, 1), "red": (1, 0, 0), "green": (0, 1, 0), "blue": (0, 0, 1)}


def level_codes(levels: int) -> list[int]:
    """``levels`` codes from 0 to 255, equally spaced and rounded.

    Examples
    --------
    >>> level_codes(5)
    [0, 64, 128, 191, 255]
    """
    if levels < 2:
        raise UserError(f"--levels must be at least 2 (black and full), got {levels}")
    return [round(255 * i / (levels - 1)) for i in range(levels)]


def patch_sequence(codes: list[int], repeats: int, channels: tuple[str, ...]) -> list[tuple[str, int, int]]:
    """(channel, code, repeat) of every patch, in the order shown: each repeat runs through every channel's levels."""
    return [(channel, code, repeat) for repeat in range(repeats) for channel in channels for code in codes]


def patch_rgb(channel: str, code: int) -> Rgb:
    mask = CHANNEL_MASKS[channel]
    return (mask[0] * code, mask[1] * code, mask[2] * code)


class _PatchLog:
    """The patch log: one flushed JSON line per patch shown."""

    def __init__(self, path: Path | None) -> None:
        self.path = path
        self._file: TextIO | None = None
        if path is not None:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            self._file = open(path, "w", encoding="ascii")  # noqa: SIM115 (a stream log, closed in close())

    def write(self, rgb: Rgb) -> None:
        if self._file is not None:
            self._file.write(json.dumps({"rgb": list(rgb)}) + "\n")
            self._file.flush()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


def _read_back(ctx: moderngl.Context, framebuffer: moderngl.Framebuffer, size: tuple[int, int]) -> Rgb:
    raw = framebuffer.read(viewport=(size[0] // 2, size[1] // 2, 1, 1), components=3, dtype="f1")
    return (raw[0], raw[1], raw[2])


def _checked(shown: Rgb, asked: Rgb, where: str) -> Rgb:
    if shown != asked:
        raise UserError(f"{where}: the framebuffer holds {list(shown)} after drawing {list(asked)}; the display "
                        "path is not 8 bits per channel (dithering, a colour profile or HDR mapping): switch those "
                        "off for the calibration, then rerun")
    return shown


class HeadlessPatches:
    """Patches in an offscreen EGL framebuffer (``--display headless``)."""

    kind = "headless"

    def __init__(self, patch_log: Path | None, size_px: tuple[int, int] = (64, 64)) -> None:
        from psyop.rendering.renderer import create_headless_context

        self.size_px = size_px
        self._log = _PatchLog(patch_log)
        try:
            self._ctx = create_headless_context()
        except Exception as exc:
            self._log.close()
            raise UserError(f"--display headless: no EGL context ({exc}); install an EGL driver (libegl1, "
                            "Mesa) or use --display window") from exc
        self._fbo = self._ctx.simple_framebuffer(size_px, components=4)

    def show(self, rgb: Rgb) -> Rgb:
        self._fbo.use()
        self._ctx.clear(rgb[0] / 255.0, rgb[1] / 255.0, rgb[2] / 255.0, 1.0)
        shown = _checked(_read_back(self._ctx, self._fbo, self.size_px), rgb, "--display headless")
        self._log.write(shown)
        return shown

    def describe(self) -> dict:
        return {"kind": self.kind, "size_px": list(self.size_px)}

    def close(self) -> None:
        self._log.close()
        self._fbo.release()
        self._ctx.release()


class WindowPatches:
    """Full-screen patches in a glfw window (``--display window``) on the display being calibrated."""

    kind = "window"

    def __init__(self, patch_log: Path | None, *, fullscreen: bool = True, settle_s: float = 0.5,
                 size_px: tuple[int, int] = (640, 480)) -> None:
        try:
            import glfw
        except ImportError as exc:
            raise UserError("--display window needs glfw: pip install 'psyop[window]'") from exc
        import moderngl

        self._glfw, self.settle_s, self.fullscreen = glfw, settle_s, fullscreen
        if not glfw.init():
            raise UserError("--display window: glfw cannot reach a display (no X or Wayland session; $DISPLAY "
                            "unset?); run on the calibrated display's desktop, or use --display headless")
        monitor = glfw.get_primary_monitor() if fullscreen else None
        if monitor:
            mode = glfw.get_video_mode(monitor)
            size_px = (int(mode.size.width), int(mode.size.height))
        glfw.window_hint(glfw.RESIZABLE, False)
        self._window = glfw.create_window(size_px[0], size_px[1], "psyop calibrate", monitor or None, None)
        if not self._window:
            glfw.terminate()
            raise UserError("--display window: glfw could not open a window; check the desktop session, or use "
                            "--display headless")
        glfw.make_context_current(self._window)
        glfw.swap_interval(1)
        self._ctx = moderngl.create_context()
        width, height = glfw.get_framebuffer_size(self._window)
        self.size_px = (int(width), int(height))
        self._log = _PatchLog(patch_log)

    def show(self, rgb: Rgb) -> Rgb:
        glfw = self._glfw
        screen = self._ctx.screen
        shown = rgb
        for k in range(2):  # both buffers of the swap chain hold the patch
            screen.use()
            self._ctx.clear(rgb[0] / 255.0, rgb[1] / 255.0, rgb[2] / 255.0, 1.0)
            if k == 0:  # the back buffer as drawn, before the swap leaves it undefined
                shown = _checked(_read_back(self._ctx, screen, self.size_px), rgb, "--display window")
            glfw.swap_buffers(self._window)
            glfw.poll_events()
        self._log.write(shown)
        deadline = time.monotonic() + self.settle_s
        while time.monotonic() < deadline:  # the display settles; events keep the window responsive
            glfw.wait_events_timeout(max(0.0, deadline - time.monotonic()))
        return shown

    def describe(self) -> dict:
        return {"kind": self.kind, "size_px": list(self.size_px), "fullscreen": self.fullscreen,
                "settle_s": self.settle_s}

    def close(self) -> None:
        self._log.close()
        self._ctx.release()
        self._glfw.destroy_window(self._window)
        self._glfw.terminate()
