"""The integrity check of a rendered frame without reading the frame back.

A session checks every image it shows: every value finite and, unless the frame is blank by
design, not uniform (``max - min > 0`` over all colour values). Reading the whole float
framebuffer back for that costs 37 MB per eye at 1440x1600 (20-42 ms on llvmpipe, against an
11.1 ms frame at 90 Hz). Instead one small GPU pass reduces each ``block_px`` x ``block_px``
block to (count of non-finite values, smallest value, largest value), and only that reduced
image is read back (1/1024 of the bytes with the default 32 px blocks). The verdict is exactly the one
the full readback gives: every pixel is visited.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import moderngl
import numpy as np

from psyop.rendering.shaders import VERTEX_SHADER

REDUCE_SHADER = """
#version 410 core
uniform sampler2D u_image;
uniform int u_block;
out vec4 reduced;
void main() {
    ivec2 size = textureSize(u_image, 0);
    ivec2 base = ivec2(gl_FragCoord.xy) * u_block;
    float bad = 0.0; float lo = 3.0e38; float hi = -3.0e38;
    for (int j = 0; j < u_block; ++j) {
        for (int k = 0; k < u_block; ++k) {
            ivec2 p = base + ivec2(k, j);
            if (p.x >= size.x || p.y >= size.y) continue;
            vec3 c = texelFetch(u_image, p, 0).rgb;
            if (any(isnan(c)) || any(isinf(c))) { bad += 1.0; continue; }
            lo = min(lo, min(c.r, min(c.g, c.b)));
            hi = max(hi, max(c.r, max(c.g, c.b)));
        }
    }
    reduced = vec4(bad, lo, hi, 1.0);
}
"""


@dataclass(frozen=True)
class FrameSummary:
    """What the check needs of one frame: non-finite pixels, smallest and largest value."""

    n_pixels: int
    n_nonfinite: int
    min_value: float
    max_value: float
    bytes_read: int

    @property
    def finite(self) -> bool:
        return self.n_nonfinite == 0

    @property
    def has_content(self) -> bool:
        """Not uniform (the full-readback test was ``np.ptp(image) > 0``)."""
        return self.max_value - self.min_value > 0.0

    def ok(self, blank_by_design: bool) -> bool:
        return self.n_pixels > 0 and self.finite and (blank_by_design or self.has_content)


def summarise_image(image: np.ndarray) -> FrameSummary:
    """The same summary from an image already on the CPU (reference for tests)."""
    rgb = np.asarray(image, dtype=np.float32)[..., :3]
    finite = np.isfinite(rgb).all(axis=-1)
    values = rgb[finite]
    return FrameSummary(int(finite.size), int((~finite).sum()),
                        float(values.min()) if values.size else math.inf,
                        float(values.max()) if values.size else -math.inf, int(rgb.nbytes))


class FrameChecker:
    """Summarises a colour texture on the GPU; reads back 1 / ``block_px``^2 of it."""

    def __init__(self, ctx: moderngl.Context, block_px: int = 32) -> None:
        self.ctx, self.block_px = ctx, int(block_px)
        self._prog = ctx.program(vertex_shader=VERTEX_SHADER, fragment_shader=REDUCE_SHADER)
        self._vao = ctx.vertex_array(self._prog, [])
        self._targets: dict[tuple[int, int], tuple[moderngl.Texture, moderngl.Framebuffer]] = {}

    def _target(self, size: tuple[int, int]) -> tuple[moderngl.Texture, moderngl.Framebuffer]:
        if size not in self._targets:
            tex = self.ctx.texture(size, 4, dtype="f4")
            self._targets[size] = (tex, self.ctx.framebuffer(color_attachments=[tex]))
        return self._targets[size]

    def summarise(self, colour: moderngl.Texture) -> FrameSummary:
        """Summary of a float colour texture (e.g. ``Renderer.colour_texture(eye)``)."""
        width, height = colour.size
        size = (-(-width // self.block_px), -(-height // self.block_px))
        _, fbo = self._target(size)
        previous = self.ctx.fbo
        fbo.use()
        self.ctx.viewport = (0, 0, *size)
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
        colour.use(0)
        cast(moderngl.Uniform, self._prog["u_image"]).value = 0
        cast(moderngl.Uniform, self._prog["u_block"]).value = self.block_px
        self._vao.render(moderngl.TRIANGLES, vertices=3)
        raw = fbo.read(components=4, dtype="f4")
        if previous is not None:
            previous.use()
        reduced = np.frombuffer(raw, dtype=np.float32).reshape(-1, 4)
        return FrameSummary(width * height, int(reduced[:, 0].sum()), float(reduced[:, 1].min()),
                            float(reduced[:, 2].max()), len(raw))

    def release(self) -> None:
        for tex, fbo in self._targets.values():
            fbo.release()
            tex.release()
        self._targets.clear()
        self._vao.release()
        self._prog.release()
