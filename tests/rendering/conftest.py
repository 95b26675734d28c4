"""Shared fixtures for the renderer tests: one EGL context per test module, Vive Pro cameras."""

from __future__ import annotations

import numpy as np
import pytest

from psyop.optics.camera import make_eye_camera
from psyop.optics.display import VIVE_PRO
from psyop.rendering.builders import direction_from_angles
from psyop.rendering.renderer import create_headless_context

IPD_M = 0.064
NC_M = 0.0076916
RIGHT_EYE_CENTRE_M = np.array([IPD_M / 2.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def gl_context():
    ctx = create_headless_context()
    yield ctx
    ctx.release()


def gaze_camera(az_deg: float, el_deg: float, mode: str, display=VIVE_PRO, eye: str = "right",
                near_m: float = 0.01, far_m: float = 100.0):
    """Camera for the right eye fixating 0.5 m away in direction (az, el) from its centre."""
    centre = RIGHT_EYE_CENTRE_M if eye == "right" else -RIGHT_EYE_CENTRE_M
    fixation = centre + direction_from_angles(az_deg, el_deg) * 0.5
    return make_eye_camera(display, eye, fixation, IPD_M, NC_M, mode, near_m, far_m)
