"""Unit conversions used throughout psyop: diopters, angles, display pixels.

All functions accept scalars or numpy arrays and return float64.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

ARCMIN_PER_DEG = 60.0


def diopters_to_m(distance_D: ArrayLike) -> np.ndarray | float:
    """Distance in metres from diopters; 0 D is optical infinity (``inf``)."""
    d = np.asarray(distance_D, dtype=np.float64)
    with np.errstate(divide="ignore"):
        out = np.where(d == 0.0, np.inf, 1.0 / np.where(d == 0.0, 1.0, d))
    return out if out.ndim else float(out)


def m_to_diopters(distance_m: ArrayLike) -> np.ndarray | float:
    """Diopters (1/m) from metres; ``inf`` gives 0 D."""
    m = np.asarray(distance_m, dtype=np.float64)
    out = 1.0 / m
    return out if out.ndim else float(out)


def deg_to_rad(angle_deg: ArrayLike) -> np.ndarray | float:
    out = np.deg2rad(np.asarray(angle_deg, dtype=np.float64))
    return out if out.ndim else float(out)


def rad_to_deg(angle_rad: ArrayLike) -> np.ndarray | float:
    out = np.rad2deg(np.asarray(angle_rad, dtype=np.float64))
    return out if out.ndim else float(out)


def deg_to_arcmin(angle_deg: ArrayLike) -> np.ndarray | float:
    out = np.asarray(angle_deg, dtype=np.float64) * ARCMIN_PER_DEG
    return out if out.ndim else float(out)


def arcmin_to_deg(angle_arcmin: ArrayLike) -> np.ndarray | float:
    out = np.asarray(angle_arcmin, dtype=np.float64) / ARCMIN_PER_DEG
    return out if out.ndim else float(out)


def rad_to_arcmin(angle_rad: ArrayLike) -> np.ndarray | float:
    return deg_to_arcmin(rad_to_deg(angle_rad))


def arcmin_per_px(fov_deg: float, width_px: int) -> float:
    """The paper's display resolution: field of view over pixels (110 deg / 1440 px = 4.58)."""
    if width_px <= 0:
        raise ValueError(f"width_px must be positive, got {width_px}")
    return float(fov_deg) * ARCMIN_PER_DEG / float(width_px)


def arcmin_to_px(angle_arcmin: ArrayLike, fov_deg: float, width_px: int) -> np.ndarray | float:
    """Angle in display pixels at the paper's uniform arcmin-per-pixel scale."""
    out = np.asarray(angle_arcmin, dtype=np.float64) / arcmin_per_px(fov_deg, width_px)
    return out if out.ndim else float(out)


def px_to_arcmin(size_px: ArrayLike, fov_deg: float, width_px: int) -> np.ndarray | float:
    """Pixels to arcmin at the paper's uniform arcmin-per-pixel scale."""
    out = np.asarray(size_px, dtype=np.float64) * arcmin_per_px(fov_deg, width_px)
    return out if out.ndim else float(out)
