"""Optics core: eye models, nodal points, eye cameras, display profiles, parallax models.

Pure numpy, float64. Imports nothing from rendering, stimulus or sessions. The geometry
(head space, eye centres, rendering modes, projection through the display's virtual image)
is described in ``docs/optics.md``.
"""

from psyop.optics.camera import EyeCamera, make_eye_camera, project_to_pixels
from psyop.optics.display import VIVE_PRO, DisplayProfile, display_profile_from_mapping, get_display_profile
from psyop.optics.eye_models import DEFAULT_EYE_MODEL, EyeModel, get_eye_model, user_eye_model
from psyop.optics.nodal import Eye, RenderingMode

__all__ = [
    "DEFAULT_EYE_MODEL",
    "VIVE_PRO",
    "DisplayProfile",
    "Eye",
    "EyeCamera",
    "EyeModel",
    "RenderingMode",
    "display_profile_from_mapping",
    "get_display_profile",
    "get_eye_model",
    "make_eye_camera",
    "project_to_pixels",
    "user_eye_model",
]
