"""The luminance and contrast a calibrated stimulus actually gets after quantisation (docs/calibration.md): what
``psyop audit`` reports per frame and a session records in session.json (``display_output.achieved``).

For every primitive whose material is in normalised luminance (a calibrated scene: ``Scene.output``), the meter
renders that primitive alone with the given camera through the final pass (the same table and dither), and reads,
over the pixels it covers wholly (its marker mask at 1, so no edge pixel counts): the intended luminance (the
ray-cast's value times the calibration's peak) and the achieved one (each pixel's integer code through the
calibration's model). It regresses achieved on intended (``L_a = alpha + beta L_i``): the achieved mean is the mean
of ``L_a``, and a pattern's achieved contrast is its nominal contrast times ``beta * mean_i / mean_a`` (the
modulation kept by the quantiser and dither, relative to the achieved mean). One frame (the renderer's first: the
dither's spatial average only), or each pixel's mean over several successive frames (the temporal dither too).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from psyop.optics.transfer import DisplayTransfer
from psyop.rendering import Renderer, RenderSettings, Scene, Solid
from psyop.rendering.scene import Grating, NoiseTexture, Primitive

if TYPE_CHECKING:
    import moderngl

    from psyop.optics.camera import EyeCamera


@dataclass(frozen=True)
class LuminanceCheck:
    """One primitive of one frame: intended and achieved mean luminance (cd/m²) and contrast (Michelson for a
    grating, the noise's peak contrast for noise, 0 for a solid), over ``pixels`` wholly covered pixels."""

    name: str
    pixels: int
    intended_cd_m2: float
    achieved_cd_m2: float
    intended_contrast: float
    achieved_contrast: float


def _nominal_contrast(material: object) -> float:
    if isinstance(material, Grating):
        return material.amplitude / material.mean if material.mean > 0 else 0.0
    if isinstance(material, NoiseTexture):
        return 2.0 * material.contrast  # psyop.stimulus.build halves the protocol's peak contrast into the RMS
    return 0.0


class LuminanceMeter:
    """Two renderers on one GL context (the primitive through the final pass, and its coverage mask), reused for
    every :meth:`measure`; a context manager."""

    def __init__(self, ctx: moderngl.Context, settings: RenderSettings | None = None) -> None:
        chosen = settings if settings is not None else RenderSettings(reuse_tolerance_px=None)
        self._renderer = Renderer(Scene(()), chosen, ctx=ctx)
        self._masks = Renderer(Scene(()), chosen, ctx=ctx)

    def __enter__(self) -> LuminanceMeter:
        return self

    def __exit__(self, *exc: object) -> None:
        self._renderer.release()
        self._masks.release()

    def measure_primitive(self, prim: Primitive, scene: Scene, camera: EyeCamera,
                          transfer: DisplayTransfer, frames: int = 1) -> LuminanceCheck | None:
        """``prim`` of the calibrated ``scene`` alone, seen from ``camera`` (None: it covers no pixel wholly); with
        ``frames`` > 1 each pixel's achieved luminance is its mean over that many successive frames (the temporal
        dither averaged too)."""
        eye = str(getattr(camera.eye, "value", camera.eye))
        self._renderer.set_scene(Scene((prim,), background=scene.background, output=scene.output))
        codes = []
        for _ in range(max(1, frames)):
            self._renderer.render(camera)
            codes.append(self._renderer.image_uint8(eye)[..., 0])
        self._masks.set_scene(Scene((dataclasses.replace(prim, material=Solid((1.0, 1.0, 1.0))),),
                                    background=(0, 0, 0)))
        self._masks.render(camera)
        inside = self._masks.image(eye)[..., 0] >= 1.0
        if not inside.any():
            return None
        intended = self._renderer.linear_image(eye)[..., 0][inside].astype(np.float64) * transfer.peak_cd_m2
        achieved = np.mean([transfer.luminance_cd_m2(c[inside].astype(np.float64)) for c in codes], axis=0)
        mean_i, mean_a = float(intended.mean()), float(achieved.mean())
        spread = float(np.var(intended))
        beta = float(np.cov(intended, achieved, bias=True)[0, 1] / spread) if spread > 0 else 0.0
        nominal = _nominal_contrast(prim.material)
        return LuminanceCheck(prim.name, int(inside.sum()), mean_i, mean_a, nominal,
                              nominal * beta * mean_i / mean_a if mean_a > 0 and spread > 0 else 0.0)

    def measure(self, scene: Scene, camera: EyeCamera, transfer: DisplayTransfer) -> tuple[LuminanceCheck, ...]:
        """The :class:`LuminanceCheck` of every solid, grating and noise primitive of a calibrated ``scene``."""
        if scene.output is None:
            return ()
        checks = (self.measure_primitive(prim, scene, camera, transfer) for prim in scene.primitives
                  if isinstance(prim.material, (Grating, NoiseTexture, Solid)))
        return tuple(c for c in checks if c is not None)


def luminance_checks(ctx: moderngl.Context, scene: Scene, camera: EyeCamera, transfer: DisplayTransfer,
                     settings: object | None = None) -> tuple[LuminanceCheck, ...]:
    """The :class:`LuminanceCheck` of every primitive of a calibrated ``scene`` seen from ``camera``."""
    with LuminanceMeter(ctx, settings if isinstance(settings, RenderSettings) else None) as meter:
        return meter.measure(scene, camera, transfer)
