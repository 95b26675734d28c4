"""The image observer's eye: the optical blur of its pupil and its accommodation error, and how acuity and
sensitivity fall with retinal eccentricity (pure numpy).

- Diffraction: the Airy pattern of a ``pupil_mm`` pupil at :data:`WAVELENGTH_M`, as the Gaussian that best fits
  its core, sd ``0.42 lambda / pupil`` (rad).
- Defocus: the geometric blur disc of diameter ``pupil x defocus_D`` (rad), as a Gaussian of the disc's sd,
  diameter / 4. ``defocus_D`` is the eye's accommodation error with respect to the display's image distance
  (every rendered surface lies at that one optical distance, whatever depth it portrays).
- Eccentricity: the minimum angle of resolution grows linearly, ``mar0 (1 + e / e2)``; the neural blur is a
  Gaussian of sd MAR / 2, and sensitivity per unit of visual field area falls as the square of the cortical
  magnification, ``(1 + e / e2) ** -2``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: the wavelength the diffraction blur is computed at (the photopic luminosity function's peak)
WAVELENGTH_M = 555e-9


@dataclass(frozen=True)
class EyeStage:
    """The stated model of the participant's eye and early vision (see the module docstring)."""

    pupil_mm: float
    defocus_D: float
    mar0_arcmin: float
    e2_deg: float

    def optical_sigma_deg(self) -> float:
        """The sd of the Gaussian point spread of diffraction and defocus together (deg)."""
        pupil_m = self.pupil_mm * 1e-3
        diffraction_rad = 0.42 * WAVELENGTH_M / pupil_m
        defocus_rad = pupil_m * abs(self.defocus_D) / 4.0
        return math.degrees(math.hypot(diffraction_rad, defocus_rad))

    def neural_sigma_deg(self, eccentricity_deg: np.ndarray) -> np.ndarray:
        """The sd of the neural blur at each eccentricity (deg): half the minimum angle of resolution there."""
        return (self.mar0_arcmin / 60.0) * (1.0 + eccentricity_deg / self.e2_deg) / 2.0

    def sigma_deg(self, eccentricity_deg: np.ndarray) -> np.ndarray:
        """The sd of the whole blur (optics, then the neural stage) at each eccentricity (deg)."""
        return np.hypot(self.optical_sigma_deg(), self.neural_sigma_deg(eccentricity_deg))

    def weight(self, eccentricity_deg: np.ndarray) -> np.ndarray:
        """Sensitivity per unit of visual field area at each eccentricity (1 at the fovea)."""
        return (1.0 + eccentricity_deg / self.e2_deg) ** -2


def pixel_directions(pixel_to_ray: np.ndarray, width_px: int, height_px: int) -> np.ndarray:
    """(H, W, 3) unit head-space directions of the pixel centres, top row first, from a camera's
    ``pixel_to_ray`` (psyop.optics.camera.EyeCamera: ``direction = M @ (u, v, 1)``, u, v in [0, 1], v down)."""
    u = (np.arange(width_px) + 0.5) / width_px
    v = (np.arange(height_px) + 0.5) / height_px
    uu, vv = np.meshgrid(u, v)
    uv1 = np.stack([uu, vv, np.ones_like(uu)], axis=-1)
    rays = uv1 @ np.asarray(pixel_to_ray, dtype=np.float64).T
    return rays / np.linalg.norm(rays, axis=-1, keepdims=True)


def eccentricity_deg(directions: np.ndarray, gaze: np.ndarray) -> np.ndarray:
    """The angle (deg) between each of ``directions`` (..., 3, unit) and the unit gaze direction ``gaze``."""
    g = np.asarray(gaze, dtype=np.float64)
    g = g / np.linalg.norm(g)
    return np.degrees(np.arccos(np.clip(directions @ g, -1.0, 1.0)))
