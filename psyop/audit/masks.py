"""Per-primitive visible area in rendered frames, with the session's own ray-casting renderer.

The renderer has no ID buffer, so visibility is measured with masks: the frame's scene is
rendered again with every primitive black except a few painted in marker colours, on a black
background and behind a black aperture. Occlusion is resolved per sample exactly as in the
participant's frame (same primitives, same order, same camera, same anti-aliasing), so a
marker's share of a pixel is that primitive's visible coverage and its sum the visible area in
pixels, edges included to the sampler's accuracy.

Packing: with S x S samples per edge pixel a pixel's value is (sum of its samples' colours) /
S^2. Each colour channel carries two primitives, one painted 1 and one painted 1 / (S^2 + 1):
the channel's value times S^2 is ``n1 + n0 / (S^2 + 1)`` with ``n0, n1`` their sample counts,
which decodes exactly (float32 keeps the sum to ~1e-4 of a sample). Six primitives per render.
A scene with an aperture (whose edge coverage scales every channel continuously) uses one
primitive per channel, three per render. Mask scenes drop the primitives' own edge effort
(``edge_samples_per_axis``, e.g. a room's 4 x 4), so every edge pixel takes the same S x S
grid: the areas are at least as accurate as the participant's frame's edges.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from psyop.rendering import Renderer, RenderSettings, Scene, Solid
from psyop.rendering.scene import Aperture

BLACK = (0.0, 0.0, 0.0)


def slots(scene: Scene) -> int:
    """Primitives per channel: 2 (packed) or 1 (with an aperture)."""
    return 1 if scene.aperture is not None else 2


def mask_scene(scene: Scene, first: int, samples_per_axis: int) -> Scene:
    """``scene`` with primitives ``first .. first + 3 * slots - 1`` in marker colours (channel
    ``k // slots``; weight 1 for the first slot, 1 / (S^2 + 1) for the second) and every other
    primitive, the background and the aperture's surround black."""
    per = slots(scene)
    low = 1.0 / (samples_per_axis**2 + 1)

    def colour(i: int) -> tuple[float, float, float]:
        k = i - first
        if not 0 <= k < 3 * per:
            return BLACK
        rgb = [0.0, 0.0, 0.0]
        rgb[k // per] = 1.0 if k % per == 0 else low
        return (rgb[0], rgb[1], rgb[2])

    # every edge pixel on the same S x S grid (no per-primitive effort), so the packing decodes
    prims = tuple(dataclasses.replace(p, material=Solid(colour(i)), edge_samples_per_axis=None)
                  for i, p in enumerate(scene.primitives))
    aperture: Aperture | None = (dataclasses.replace(scene.aperture, colour=BLACK)
                                 if scene.aperture is not None else None)
    return Scene(prims, background=BLACK, aperture=aperture)


def decode(channel: np.ndarray, samples_per_axis: int, per: int) -> list[np.ndarray]:
    """Per-pixel coverage (0..1) of the ``per`` primitives packed in one channel."""
    if per == 1:
        return [channel.astype(np.float64)]
    s2 = samples_per_axis**2
    base = s2 + 1
    v = channel.astype(np.float64) * s2
    n1 = np.floor(v + 0.5 / base)
    n0 = np.round((v - n1) * base)
    return [n1 / s2, n0 / s2]


class FrameMeasurer:
    """Renders one frame's colour image and its per-primitive visible areas (two renderers on
    one context: colour scenes keep their textures, mask scenes have none)."""

    def __init__(self, ctx: Any, settings: RenderSettings | None = None) -> None:
        self.settings = settings or RenderSettings(reuse_tolerance_px=None)
        self._colour = Renderer(Scene(()), self.settings, ctx=ctx)
        self._masks = Renderer(Scene(()), self.settings, ctx=ctx)

    def colour(self, scene: Scene, camera: Any) -> np.ndarray:
        """The participant's frame, (H, W, 3) float32."""
        self._colour.set_scene(scene)
        self._colour.render(camera)
        return self._colour.image(_eye(camera))

    def visible_areas_px(self, scene: Scene, camera: Any) -> np.ndarray:
        """(n,) visible area of every primitive in this frame, in pixels of ``camera``."""
        n = len(scene.primitives)
        per = slots(scene)
        s = int(self.settings.samples_per_axis)
        areas = np.zeros(n)
        for first in range(0, n, 3 * per):
            self._masks.set_scene(mask_scene(scene, first, s))
            self._masks.render(camera)
            img = self._masks.image(_eye(camera))
            for channel in range(3):
                for slot, cover in enumerate(decode(img[..., channel], s, per)):
                    i = first + channel * per + slot
                    if i < n:
                        areas[i] = float(cover.sum())
        return areas

    def release(self) -> None:
        self._colour.release()
        self._masks.release()


def _eye(camera: Any) -> str:
    eye = getattr(camera, "eye", "right")
    return str(getattr(eye, "value", eye))
