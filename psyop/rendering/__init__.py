"""Ray-casting renderer for analytic VR psychophysics scenes (see docs/rendering.md)."""

from psyop.rendering.renderer import FrameResult, Renderer, RenderSettings, RenderStats
from psyop.rendering.scene import (
    Aperture,
    GridMaterial,
    ImageTexture,
    NoiseKind,
    NoiseTexture,
    Primitive,
    Scene,
    Shape,
    SineBorder,
    Solid,
)
from psyop.rendering.shaders import AntiAliasing

__all__ = [
    "AntiAliasing", "Aperture", "FrameResult", "GridMaterial", "ImageTexture", "NoiseKind", "NoiseTexture",
    "Primitive", "RenderSettings", "RenderStats", "Renderer", "Scene", "Shape", "SineBorder", "Solid",
]
