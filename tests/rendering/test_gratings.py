"""Gratings drawn in the fragment shader (psyop.rendering.scene.Grating, docs/gratings_and_luminance.md).

Every number is read off rendered pixels and compared with the analytic grating at the surface point each pixel's
central ray hits (psyop.rendering.camera_math.pixel_rays), so the test checks the shader against the definition of
surface degrees, not against the scene description's own arithmetic.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from psyop.optics.camera import make_eye_camera
from psyop.optics.display import symmetric_profile
from psyop.rendering import Renderer, Scene
from psyop.rendering.builders import placed_primitive
from psyop.rendering.camera_math import pixel_rays
from psyop.rendering.measure import FIXTURE_IPD_M, NC_M, RIGHT_CENTRE_M
from psyop.rendering.scene import Grating, Shape, Waveform, WindowKind
from psyop.stimulus.build import surface_deg_per_unit

#: a small display straight ahead: 0.078 deg per pixel at its centre (Nyquist 6.4 cycles/deg)
DISPLAY = symmetric_profile("grating_test", 512, 512, 90.0, 40.0)
DISTANCE_M = 1.0


def _camera():
    return make_eye_camera(DISPLAY, "right", RIGHT_CENTRE_M + np.array([0.0, 0.0, -1.0]), FIXTURE_IPD_M, NC_M,
                           "conventional")


def _grating(cpd: float, orientation_deg: float = 0.0, phase_deg: float = 0.0, size_deg: float = 30.0,
             waveform: Waveform = Waveform.SINE, window: WindowKind = WindowKind.NONE, w1: float = 0.0,
             w2: float = 0.0, mean: float = 0.5, contrast: float = 0.8) -> Grating:
    theta = math.radians(orientation_deg)
    return Grating(mean=mean, amplitude=mean * contrast, cycles_u=cpd * math.cos(theta),
                   cycles_v=cpd * math.sin(theta), deg_per_unit_u=surface_deg_per_unit(size_deg),
                   deg_per_unit_v=surface_deg_per_unit(size_deg), phase_cycles=phase_deg / 360.0,
                   waveform=waveform, window=window, window_1=w1, window_2=w2)


def _render(gl_context, grating: Grating, size_deg: float = 30.0, shape: Shape = Shape.RECT):
    prim = placed_primitive(shape, DISTANCE_M, size_deg, size_deg, grating, origin_m=RIGHT_CENTRE_M, name="g")
    camera = _camera()
    with Renderer(Scene((prim,), background=(0.0, 0.0, 0.0)), ctx=gl_context) as renderer:
        renderer.render(camera)
        image = renderer.image()[..., 0].astype(np.float64)
    return image, camera, prim


def _surface_deg(camera, prim, deg_per_unit: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) surface degrees of the point each pixel centre's ray hits on the primitive's plane, float64
    (``deg_per_unit``: for a primitive that is no grating, its surface degrees per local unit)."""
    h, w = camera.height_px, camera.width_px
    ys, xs = np.mgrid[0:h, 0:w]
    d = pixel_rays(camera, np.stack([xs.ravel() + 0.5, ys.ravel() + 0.5], axis=-1))
    cop = np.asarray(camera.centre_of_projection_m, dtype=np.float64)
    c, u, v = (np.asarray(x, dtype=np.float64) for x in (prim.centre_m, prim.half_u_m, prim.half_v_m))
    n = np.cross(u, v)
    t = ((c - cop) @ n) / (d @ n)
    r = cop + t[:, None] * d - c
    a, b = r @ u / (u @ u), r @ v / (v @ v)
    du = deg_per_unit if deg_per_unit is not None else prim.material.deg_per_unit_u
    dv = deg_per_unit if deg_per_unit is not None else prim.material.deg_per_unit_v
    return (a * du).reshape(h, w), (b * dv).reshape(h, w)


def _interior(x: np.ndarray, y: np.ndarray, half_deg: float, margin_deg: float = 0.5) -> np.ndarray:
    return (np.abs(x) < half_deg - margin_deg) & (np.abs(y) < half_deg - margin_deg)


@pytest.mark.parametrize("orientation_deg, phase_deg", [(0.0, 0.0), (30.0, 90.0), (-75.0, 200.0)])
def test_sine_pixels_equal_the_analytic_grating(gl_context, orientation_deg, phase_deg):
    """Away from the primitive's edge each pixel is one ray at its centre: the rendered value equals the analytic
    sine at the surface point that ray hits, within 5e-5 of full scale (float32 ray and phase arithmetic; measured
    at most 1.8e-5 over 30 cycles, 0.005 of an 8-bit step)."""
    grating = _grating(2.0, orientation_deg, phase_deg)
    image, camera, prim = _render(gl_context, grating)
    x, y = _surface_deg(camera, prim)
    inside = _interior(x, y, surface_deg_per_unit(30.0))  # the quad's half-extent in surface degrees
    expected = grating.value(x, y)
    error = np.abs(image - expected)[inside]
    assert inside.sum() > 100_000
    assert error.max() < 5e-5, error.max()


def test_measured_spatial_frequency_is_cycles_per_deg(gl_context):
    """Zero crossings along the middle row, located to a fraction of a pixel, converted to surface degrees through
    each pixel's ray: 1 / mean spacing equals cycles_per_deg to 0.05 % (bound 1 %); in visual angle from the eye
    within 3 deg of straight ahead (where a surface degree and a degree of visual angle agree to 0.1 %) to 1 %."""
    cpd = 1.7
    image, camera, prim = _render(gl_context, _grating(cpd, contrast=1.0))
    row = camera.height_px // 2
    values = image[row] - 0.5
    x, _ = _surface_deg(camera, prim)
    xs = x[row]
    inside = np.abs(xs) < 14.0
    idx = np.flatnonzero(inside[:-1] & inside[1:] & (np.sign(values[:-1]) != np.sign(values[1:])))
    frac = values[idx] / (values[idx] - values[idx + 1])
    crossings = xs[idx] + frac * (xs[idx + 1] - xs[idx])
    slope = np.polyfit(np.arange(len(crossings)), crossings, 1)[0]  # surface degrees per half cycle
    measured = 1.0 / (2.0 * slope)
    assert len(crossings) > 80
    assert measured == pytest.approx(cpd, rel=5e-4)
    # visual angle seen from the centre of projection (the eye's centre of rotation here), near straight ahead
    cop = np.asarray(camera.centre_of_projection_m)
    d = pixel_rays(camera, np.stack([idx + 0.5 + frac, np.full(len(idx), row + 0.5)], axis=-1))
    azimuth_deg = np.degrees(np.arctan2(d[:, 0], -d[:, 2]))
    centre_az = math.degrees(math.atan2(prim.centre_m[0] - cop[0], -(prim.centre_m[2] - cop[2])))
    near = np.abs(azimuth_deg - centre_az) < 3.0
    angular = 1.0 / (2.0 * np.polyfit(np.arange(near.sum()), azimuth_deg[near], 1)[0])
    assert angular == pytest.approx(cpd, rel=0.01)


def test_orientation_and_phase_move_the_pattern_as_stated(gl_context):
    """orientation 0: vertical bars (constant down each column); 90: horizontal bars. phase_deg 90 moves the
    pattern by a quarter period towards -x (its value at the centre goes from the mean to the peak)."""
    vertical, camera, prim = _render(gl_context, _grating(1.0, 0.0))
    horizontal, _, _ = _render(gl_context, _grating(1.0, 90.0))
    x, y = _surface_deg(camera, prim)
    inside = _interior(x, y, 14.0)
    rows = slice(200, 312)
    assert np.ptp(vertical[rows, 256]) < 0.01 < np.ptp(vertical[256, 100:400])
    assert np.ptp(horizontal[256, 100:400]) < 0.01 < np.ptp(horizontal[rows, 256])
    shifted, _, _ = _render(gl_context, _grating(1.0, 0.0, 90.0))
    # the shifted image equals the first one sampled a quarter period (0.25 deg) further along +x
    moved = _grating(1.0, 0.0, 0.0).value(x + 0.25, y)
    assert np.abs(shifted - moved)[inside].max() < 5e-5
    # orientation 30 deg: the value is constant along the bars' direction (-sin 30, cos 30)
    oblique = _grating(1.0, 30.0)
    along = oblique.value(x - 0.7 * math.sin(math.radians(30)), y + 0.7 * math.cos(math.radians(30)))
    rendered, _, _ = _render(gl_context, oblique)
    assert np.abs(rendered - along)[inside].max() < 5e-5


def test_gaussian_window_profile_matches_sigma(gl_context):
    """A Gabor: wherever the carrier is at least 0.7 of its peak, (value - mean) / (amplitude * carrier) is the
    envelope; it equals exp(-r^2 / (2 sigma^2)) to 1e-4, and a Gaussian fitted to it (log-linear in r^2, where it
    exceeds 0.05) gives sigma within 0.5 %."""
    sigma = 2.5
    gabor = _grating(2.0, 20.0, 90.0, window=WindowKind.GAUSSIAN, w1=sigma, contrast=0.9)
    image, camera, prim = _render(gl_context, gabor)
    x, y = _surface_deg(camera, prim)
    inside = _interior(x, y, 14.0)
    carrier = np.sin(2 * np.pi * (x * gabor.cycles_u + y * gabor.cycles_v + gabor.phase_cycles))
    use = inside & (np.abs(carrier) > 0.7)
    envelope = (image[use] - gabor.mean) / (gabor.amplitude * carrier[use])
    r2 = x[use] ** 2 + y[use] ** 2
    assert np.abs(envelope - np.exp(-0.5 * r2 / sigma**2)).max() < 1e-4
    keep = envelope > 0.05
    fit = np.polyfit(r2[keep], np.log(envelope[keep]), 1)
    assert math.sqrt(-0.5 / fit[0]) == pytest.approx(sigma, rel=5e-3)


def test_raised_cosine_window_and_disc_edges(gl_context):
    """A raised-cosine Gabor on a disc: flat (w = 1) inside the plateau, 0.5 half-way down the ramp, 0 beyond;
    the disc's edge stays the ray-cast edge (edge pixels hold the covered share of the background-mean mix)."""
    gabor = _grating(1.0, 0.0, 90.0, size_deg=20.0, window=WindowKind.RAISED_COSINE, w1=4.0, w2=4.0, contrast=1.0)
    image, camera, prim = _render(gl_context, gabor, size_deg=20.0, shape=Shape.DISC)
    x, y = _surface_deg(camera, prim)
    r = np.hypot(x, y)
    inner = r < 9.5
    assert np.abs(image - gabor.value(x, y))[inner].max() < 5e-5
    # beyond the ramp only the mean is left, up to the disc's edge
    ring = (r > 8.2) & (r < 9.5)
    assert np.abs(image[ring] - gabor.mean).max() < 1e-6
    outside = r > 10.5
    assert image[outside].max() == 0.0


def test_square_wave_is_box_filtered_over_the_pixel(gl_context):
    """A square wave's edges fall inside pixels: each interior pixel holds the pixel-footprint average along the
    modulation (between the two levels), and the image's row mean equals the grating's mean within 0.002."""
    square = _grating(0.9, 0.0, 0.0, waveform=Waveform.SQUARE, contrast=1.0)
    image, camera, prim = _render(gl_context, square)
    x, y = _surface_deg(camera, prim)
    inside = _interior(x, y, 14.0)
    levels = image[inside]
    assert np.any((levels > 0.05) & (levels < 0.95))  # partial pixels at the bars' edges
    # box filter: mean over whole periods equals the mean
    row = image[256, 60:452]
    period_px = 1.0 / 0.9 / (x[256, 257] - x[256, 256])
    whole = int(np.floor(len(row) / period_px) * period_px)
    assert row[:whole].mean() == pytest.approx(0.5, abs=0.01)
    # point-sampled where the footprint is 0 (the analytic form with h = 0): bars are 0 or 1 away from edges
    far_from_edge = np.abs(np.sin(2 * np.pi * 0.9 * x)) > 0.3
    assert np.abs(image - square.value(x, y))[inside & far_from_edge].max() < 1e-5
