"""The luminance and contrast each stimulus actually gets after quantisation, on a calibrated display
(docs/gratings_and_luminance.md): part of ``psyop audit``'s output.

For every primitive whose material is in normalised luminance (a calibrated scene: ``Scene.output``), the audit renders
that primitive alone with the frame's camera through the final pass (the same table and dither), and reads, over the
pixels it covers wholly (its marker mask at 1, so no edge pixel counts): the intended luminance (the ray-cast's value
times the calibration's peak) and the achieved one (each pixel's integer code through the calibration's model). It
regresses achieved on intended (``L_a = alpha + beta L_i``): the achieved mean is the mean of ``L_a``, and a pattern's
achieved contrast is its nominal contrast times ``beta * mean_i / mean_a`` (the modulation kept by the quantiser and
dither, relative to the achieved mean). One frame: the dither's spatial average only.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from psyop.optics.transfer import DisplayTransfer
from psyop.rendering import Renderer, Scene, Solid
from psyop.rendering.scene import Grating, NoiseTexture

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


def luminance_checks(ctx: moderngl.Context, scene: Scene, camera: EyeCamera, transfer: DisplayTransfer,
                     settings: object | None = None) -> tuple[LuminanceCheck, ...]:
    """The :class:`LuminanceCheck` of every primitive of a calibrated ``scene`` seen from ``camera``."""
    from psyop.rendering import RenderSettings

    if scene.output is None:
        return ()
    render_settings = settings if isinstance(settings, RenderSettings) else RenderSettings(reuse_tolerance_px=None)
    eye = str(getattr(camera.eye, "value", camera.eye))
    out: list[LuminanceCheck] = []
    with Renderer(Scene(()), render_settings, ctx=ctx) as renderer, \
            Renderer(Scene(()), render_settings, ctx=ctx) as masks:
        for prim in scene.primitives:
            if not isinstance(prim.material, (Grating, NoiseTexture, Solid)):
                continue
            renderer.set_scene(Scene((prim,), background=scene.background, output=scene.output))
            renderer.render(camera)
            masks.set_scene(Scene((dataclasses.replace(prim, material=Solid((1.0, 1.0, 1.0))),), background=(0, 0, 0)))
            masks.render(camera)
            inside = masks.image(eye)[..., 0] >= 1.0
            if not inside.any():
                continue
            intended = renderer.linear_image(eye)[..., 0][inside].astype(np.float64) * transfer.peak_cd_m2
            achieved = transfer.luminance_cd_m2(renderer.image_uint8(eye)[..., 0][inside].astype(np.float64))
            mean_i, mean_a = float(intended.mean()), float(achieved.mean())
            spread = float(np.var(intended))
            beta = float(np.cov(intended, achieved, bias=True)[0, 1] / spread) if spread > 0 else 0.0
            nominal = _nominal_contrast(prim.material)
            out.append(LuminanceCheck(prim.name, int(inside.sum()), mean_i, mean_a, nominal,
                                      nominal * beta * mean_i / mean_a if mean_a > 0 and spread > 0 else 0.0))
    return tuple(out)


def luminance_table(checks: list[tuple[str, LuminanceCheck]]) -> list[str]:
    """Lines of the audit's luminance table: per frame label and primitive, intended and achieved."""
    if not checks:
        return []
    lines = ["luminance after quantisation (calibrated display; one frame, fully covered pixels):",
             f"{'frame':<40} {'primitive':<16} {'pixels':>7} {'mean cd/m2 intended':>20} {'achieved':>9} "
             f"{'contrast % intended':>20} {'achieved':>9}"]
    for label, c in checks:
        lines.append(f"{label:<40} {c.name:<16} {c.pixels:>7d} {c.intended_cd_m2:>20.4f} {c.achieved_cd_m2:>9.4f} "
                     f"{100 * c.intended_contrast:>20.4f} {100 * c.achieved_contrast:>9.4f}")
    return lines
