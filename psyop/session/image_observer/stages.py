"""The image observer's validated parameters (psyop.protocol.image_observer) as the stages of its model: the eye
(psyop.session.image_observer.eye) and the relative-motion stage (psyop.session.image_observer.response)."""

from __future__ import annotations

from psyop.protocol.image_observer import ImageObserver
from psyop.session.image_observer.eye import EyeStage
from psyop.session.image_observer.response import MotionStage
from psyop.session.rows import JsonMapping


def model_of(params: JsonMapping) -> ImageObserver:
    """The observer's parameters (the plan's ``observer:`` section) as their validated model."""
    return ImageObserver.model_validate({k: v for k, v in params.items() if k in ImageObserver.model_fields})


def stages_of(model: ImageObserver) -> tuple[EyeStage, MotionStage]:
    """The eye and the relative-motion stage the parameters state."""
    eye = EyeStage(pupil_mm=float(model.pupil_mm), defocus_D=float(model.defocus_D),
                   mar0_arcmin=float(model.mar0_arcmin), e2_deg=float(model.e2_deg))
    motion = MotionStage(scale_deg=float(model.motion_scale_deg), window_deg=float(model.motion_window_deg),
                         pursued_deg=float(model.pursued_deg), luminance_weight=float(model.luminance_weight))
    return eye, motion
