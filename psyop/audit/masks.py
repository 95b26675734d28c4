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

Small primitives: at the audit's default scale (0.125) a pixel is about 0.6 deg on the Vive
Pro, so a 0.5 deg target covers a fraction of one pixel and S x S samples count its area to tens
of percent. A primitive whose screen box spans fewer than :data:`MIN_SAMPLES_ACROSS` edge
samples is therefore measured again in a magnified window around it (:func:`zoom_camera`: the
same rays and projection, finer pixels), occluders included, until it spans that many (at most
:data:`MAX_MAGNIFICATION`-fold); its area is the window's sum / magnification^2.
``tests/test_audit.py`` checks discs, eye-facing discs and rects of 0.5-3 deg against exact
projected areas to 2 %.
"""

from __future__ import annotations

import dataclasses

import moderngl
import numpy as np

from psyop.audit.meshes import (MSAA_SAMPLES_PER_AXIS, MarkerAssets, compare, MeshCheck, measure_window,
                                mesh_mask_scene, mesh_screen_box_px, not_compared,
                                silhouette_scene)
from psyop.optics.camera import EyeCamera
from psyop.rendering import Renderer, RenderSettings, Scene, Solid
from psyop.rendering.camera_math import crop_camera
from psyop.rendering.scene import Aperture
from psyop.rendering.screen_bounds import UNBOUNDED_PX, screen_bounds_px

BLACK = (0.0, 0.0, 0.0)
#: A primitive whose screen box spans fewer edge samples than this (pixels x S, either axis) is
#: measured again in a magnified window that makes it span them: an axis-aligned edge's sampling
#: error is up to half a sample along the edge, so a primitive L samples across is off by at
#: most ~2 / L of its area (0.8 % at 256; the audit's target is 2 %).
MIN_SAMPLES_ACROSS = 256.0
#: Largest magnification of a small primitive's window (pixels of the window per frame pixel):
#: at the default scale and S = 16 a 0.5 deg target (~0.8 px) then spans ~200 samples.
MAX_MAGNIFICATION = 16
#: Most pixels in a magnified window (a long thin primitive is magnified less): what a window costs.
MAX_WINDOW_PIXELS = 128 * 128


def slots(scene: Scene) -> int:
    """Primitives per channel: 2 (packed) or 1 (with an aperture, or with meshes: their anti-aliased
    edges and occlusion scale a channel continuously too)."""
    return 1 if scene.aperture is not None or scene.meshes else 2


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


def zoom_camera(camera: EyeCamera, x0_px: int, y0_px: int, width_px: int, height_px: int, magnification: int) -> EyeCamera:
    """The pixel window ``x0 .. x0 + width``, ``y0 .. y0 + height`` of ``camera`` rendered with
    ``magnification`` x ``magnification`` pixels per pixel: the same rays and projection as the
    full frame (:func:`psyop.rendering.camera_math.crop_camera`), a finer pixel grid."""
    crop = crop_camera(camera, x0_px, y0_px, width_px, height_px)
    return dataclasses.replace(crop, width_px=int(width_px * magnification), height_px=int(height_px * magnification))


def screen_boxes_px(scene: Scene, camera: EyeCamera) -> np.ndarray:
    """(n, 4) conservative boxes (x_min, y_min, x_max, y_max) of the primitives in ``camera``'s pixels."""
    if not scene.primitives:
        return np.zeros((0, 4))
    cop = np.asarray(camera.centre_of_projection_m, dtype=np.float64)
    rel = np.array([np.asarray(p.centre_m, float) - (0.0 if p.at_infinity else 1.0) * cop for p in scene.primitives])
    hu = np.array([p.half_u_m for p in scene.primitives], float)
    hv = np.array([p.half_v_m for p in scene.primitives], float)
    return screen_bounds_px(rel, hu, hv, camera.pixel_to_ray, int(camera.width_px), int(camera.height_px))


def zoom_window(box_px: np.ndarray, width_px: int, height_px: int, samples_per_axis: int
                ) -> tuple[int, int, int, int, int] | None:
    """(x0, y0, w, h, magnification) of the magnified window for a primitive's screen box, or
    None when it needs none (box at least :data:`MIN_SAMPLES_ACROSS` samples wide and high,
    unbounded, off the image, or too long to magnify within :data:`MAX_WINDOW_PIXELS`).

    Examples
    --------
    >>> zoom_window(np.array([10.2, 20.5, 10.8, 21.1]), 180, 200, 16)
    (9, 19, 3, 4, 16)
    >>> zoom_window(np.array([0.0, 0.0, 100.0, 80.0]), 180, 200, 16) is None
    True
    """
    x_min, y_min, x_max, y_max = (float(v) for v in box_px)
    if max(abs(x_min), abs(y_min), abs(x_max), abs(y_max)) >= UNBOUNDED_PX:
        return None
    extent = min(x_max - x_min, y_max - y_min)
    min_extent_px = MIN_SAMPLES_ACROSS / samples_per_axis
    if extent >= min_extent_px:
        return None
    x0, y0 = max(int(np.floor(x_min)) - 1, 0), max(int(np.floor(y_min)) - 1, 0)
    x1, y1 = min(int(np.ceil(x_max)) + 1, width_px), min(int(np.ceil(y_max)) + 1, height_px)
    if x1 <= x0 or y1 <= y0:
        return None
    magnification = int(min(MAX_MAGNIFICATION, np.ceil(min_extent_px / max(extent, 1e-9)),
                            np.floor(np.sqrt(MAX_WINDOW_PIXELS / ((x1 - x0) * (y1 - y0))))))
    if magnification < 2:
        return None
    return x0, y0, x1 - x0, y1 - y0, magnification


class FrameMeasurer:
    """Renders one frame's colour image and its per-primitive visible areas (two renderers on
    one context: colour scenes keep their textures, mask scenes have none)."""

    def __init__(self, ctx: moderngl.Context | None, settings: RenderSettings | None = None) -> None:
        self.settings = settings or RenderSettings(reuse_tolerance_px=None)
        self._colour = Renderer(Scene(()), self.settings, ctx=ctx)
        self._masks = Renderer(Scene(()), self.settings, ctx=ctx)
        self._zoom = Renderer(Scene(()), self.settings, ctx=ctx)
        self._mesh = Renderer(Scene(()), self.settings, ctx=ctx)
        self._markers = MarkerAssets()

    def colour(self, scene: Scene, camera: EyeCamera) -> np.ndarray:
        """The participant's frame, (H, W, 3) float32."""
        self._colour.set_scene(scene)
        self._colour.render(camera)
        return self._colour.image(_eye(camera))

    def visible_areas_px(self, scene: Scene, camera: EyeCamera, zoom: bool = True) -> np.ndarray:
        """(n,) visible area of every primitive in this frame, in pixels of ``camera``; with
        ``zoom``, primitives narrower than :data:`MIN_SAMPLES_ACROSS` samples are measured in a
        magnified window (:func:`zoom_window`)."""
        n = len(scene.primitives)
        per = slots(scene)
        s = int(self.settings.samples_per_axis)
        areas = np.zeros(n)
        for first in range(0, n, 3 * per):
            self._masks.set_scene(self._mask(scene, first))
            self._masks.render(camera)
            img = self._masks.image(_eye(camera))
            for channel in range(3):
                for slot, cover in enumerate(decode(img[..., channel], s, per)):
                    i = first + channel * per + slot
                    if i < n:
                        areas[i] = float(cover.sum())
        if zoom:
            for i, box in enumerate(screen_boxes_px(scene, camera)):
                window = zoom_window(box, int(camera.width_px), int(camera.height_px), s)
                if window is not None:
                    areas[i] = self._zoomed_area_px(scene, camera, i, window)
        return areas

    def _zoomed_area_px(self, scene: Scene, camera: EyeCamera, index: int, window: tuple[int, int, int, int, int]) -> float:
        x0, y0, w, h, magnification = window
        masks = self._mask(scene, index)
        if masks.aperture is not None:  # the renderer keeps a screen-fixed aperture mask per eye and
            # image size; a new window needs a new one, recomputed when the aperture changes
            self._zoom.set_scene(dataclasses.replace(masks, aperture=None))
        self._zoom.set_scene(masks)
        cam = zoom_camera(camera, x0, y0, w, h, magnification)
        self._zoom.render(cam)
        img = self._zoom.image(_eye(cam))
        cover = decode(img[..., 0], int(self.settings.samples_per_axis), slots(scene))[0]
        return float(cover.sum()) / magnification**2

    def _mask(self, scene: Scene, first: int) -> Scene:
        """:func:`mask_scene` with the scene's meshes drawn black (they occlude the primitives as in the frame)."""
        mask = mask_scene(scene, first, int(self.settings.samples_per_axis))
        if not scene.meshes:
            return mask
        return silhouette_scene(dataclasses.replace(mask, meshes=scene.meshes), self._markers)

    def mesh_checks(self, scene: Scene, camera: EyeCamera, exact_scene: Scene | None = None) -> tuple[MeshCheck, ...]:
        """Every mesh's rendered visible area in this frame against the exact one (:mod:`psyop.audit.meshes`),
        in pixels of ``camera``. ``exact_scene``: the geometry the reference is computed from (default
        ``scene``; a test passes a moved mesh to see the check fail)."""
        exact_scene = silhouette_scene(scene if exact_scene is None else exact_scene, self._markers)
        base = self._mask(scene, len(scene.primitives))  # every primitive black
        out = []
        for index, inst in enumerate(scene.meshes):
            why = not_compared(scene, inst)
            if why:
                out.append(MeshCheck(inst.name, 0.0, 0.0, 0.0, skipped=why))
                continue
            w, h = int(camera.width_px), int(camera.height_px)
            window = zoom_window(mesh_screen_box_px(inst, camera), w, h, MSAA_SAMPLES_PER_AXIS)
            x0, y0, ww, wh, mag = window if window is not None else (0, 0, w, h, 1)
            cam = camera if window is None else zoom_camera(camera, x0, y0, ww, wh, mag)
            rendered, exact = measure_window(self._mesh, mesh_mask_scene(base, scene, index, self._markers),
                                             exact_scene, inst.name, cam, _eye(cam))
            out.append(compare(inst.name, rendered, exact, mag))
        return tuple(out)

    def release(self) -> None:
        self._colour.release()
        self._masks.release()
        self._zoom.release()
        self._mesh.release()


def _eye(camera: EyeCamera) -> str:
    eye = getattr(camera, "eye", "right")
    return str(getattr(eye, "value", eye))
