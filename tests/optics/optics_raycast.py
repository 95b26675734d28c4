"""Independent reference geometry for the optics tests.

Written from the definitions only (line-plane intersection with the display's virtual-image
rectangle); it deliberately imports nothing from psyop.optics.camera.
"""

from __future__ import annotations

import math

import numpy as np


def rectangle(tangents, eye_centre, d_m):
    """Corners of the virtual-image rectangle: x0, x1, y0 (bottom), y1 (top), z (plane)."""
    l, r, b, t = tangents
    cx = eye_centre[0]
    return cx + d_m * l, cx + d_m * r, d_m * b, d_m * t, -d_m


def raycast_pixel(point, cop, tangents, eye_centre, d_m, width_px, height_px):
    """Pixel (x right, y down) where the ray from ``cop`` through ``point`` meets the image."""
    point = np.asarray(point, dtype=np.float64)
    cop = np.asarray(cop, dtype=np.float64)
    l, r, b, t = tangents
    if math.isinf(d_m):
        # Image at infinity: the pixel depends only on the direction of the ray.
        direction = point - cop
        tx = direction[0] / -direction[2]
        ty = direction[1] / -direction[2]
        u = (tx - l) / (r - l)
        v = (t - ty) / (t - b)
    else:
        x0, x1, y0, y1, z_plane = rectangle(tangents, eye_centre, d_m)
        s = (z_plane - cop[2]) / (point[2] - cop[2])  # line-plane intersection parameter
        hit = cop + s * (point - cop)
        u = (hit[0] - x0) / (x1 - x0)
        v = (y1 - hit[1]) / (y1 - y0)
    return np.array([u * width_px, v * height_px])


def raycast_direction(u, v, cop, tangents, eye_centre, d_m):
    """Unit direction from ``cop`` through normalised image position (u, v)."""
    l, r, b, t = tangents
    if math.isinf(d_m):
        direction = np.array([l + u * (r - l), t - v * (t - b), -1.0])
    else:
        x0, x1, y0, y1, z_plane = rectangle(tangents, eye_centre, d_m)
        target = np.array([x0 + u * (x1 - x0), y1 - v * (y1 - y0), z_plane])
        direction = target - np.asarray(cop, dtype=np.float64)
    return direction / np.linalg.norm(direction)


def nodal_reference(fixation_point, eye_centre, nc_m):
    """Paper eq. 1 for a finite fixation point, from the definition."""
    f_eye = np.asarray(fixation_point, dtype=np.float64) - np.asarray(eye_centre, dtype=np.float64)
    return nc_m * f_eye / math.sqrt(float(f_eye @ f_eye))
