"""The renderer's output: values written as they are without a calibration; through the calibration's inverse and
an ordered dither with one (psyop.rendering.scene.OutputTransfer, docs/gratings_and_luminance.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from psyop.protocol.luminance import load_transfer
from psyop.rendering import Renderer, RenderSettings, Scene, Solid
from psyop.rendering.builders import placed_primitive
from psyop.rendering.measure import RIGHT_CENTRE_M
from psyop.rendering.scene import Grating, OutputTransfer, Shape, WindowKind
from psyop.stimulus.build import surface_deg_per_unit
from psyop.stimulus.output import Output

from tests.protocol.calibration_files import power_law, write_calibration
from tests.rendering.test_gratings import _camera, _surface_deg

NO_REUSE = RenderSettings(reuse_tolerance_px=None)


def test_without_a_calibration_values_are_written_as_they_are(gl_context):
    """The current transfer: the float image holds the values given (no sRGB encoding, no gamma) and 8 bits are
    round(255 v); no final pass runs (no linear target)."""
    values = (0.0, 0.2, 0.5, 127.5 / 255.0, 0.73, 1.0)
    prims = tuple(placed_primitive(Shape.RECT, 1.0, 3.0, 3.0, Solid((v, v, v)), -10.0 + 4.0 * k, 0.0,
                                   RIGHT_CENTRE_M, name=f"p{k}") for k, v in enumerate(values))
    camera = _camera()
    with Renderer(Scene(prims, background=(0.25, 0.25, 0.25)), ctx=gl_context) as renderer:
        renderer.render(camera)
        image, codes = renderer.image(), renderer.image_uint8()
        assert renderer._eyes["right"].linear is None
    for k, v in enumerate(values):
        x, y = _surface_deg(camera, prims[k], surface_deg_per_unit(3.0))
        inside = (np.abs(x) < 1.2) & (np.abs(y) < 1.2)
        assert np.all(image[inside] == np.float32(v))
        assert np.all(codes[inside] == round(255 * v))


@pytest.fixture(scope="module")
def known_display(tmp_path_factory):
    """The known display (gamma 2.4, black 0.3, peak 100 cd/m²) and the transfer its calibration file gives."""
    path = write_calibration(tmp_path_factory.mktemp("cal") / "cal.json", power_law())
    return power_law(), load_transfer(path)


def test_pixel_values_keep_their_codes_on_a_calibrated_display(gl_context, known_display):
    """A colour given as pixel values shows its own code through the final pass (no dither on exact codes)."""
    _, transfer = known_display
    output = Output(transfer)
    codes_in = (0, 1, 17, 64, 128, 200, 254, 255)
    prims = tuple(placed_primitive(Shape.RECT, 1.0, 2.0, 2.0, Solid(output.pixel_rgb((c / 255.0,) * 3)),
                                   -12.0 + 3.0 * k, 0.0, RIGHT_CENTRE_M, name=f"p{k}") for k, c in enumerate(codes_in))
    camera = _camera()
    scene = Scene(prims, background=output.pixel_rgb((0.5, 0.5, 0.5)), output=output.scene_output())
    with Renderer(scene, ctx=gl_context) as renderer:
        renderer.render(camera)
        codes = renderer.image_uint8()[..., 0]
    for k, c in enumerate(codes_in):
        x, y = _surface_deg(camera, prims[k], surface_deg_per_unit(2.0))
        inside = (np.abs(x) < 0.8) & (np.abs(y) < 0.8)
        assert np.all(codes[inside] == c), (c, np.unique(codes[inside]))
    assert codes[5, 5] == 128  # the background, 0.5 -> code 128


def _gabor(output: Output, contrast: float) -> Grating:
    mean = output.luminance_value(40.0)
    return Grating(mean=mean, amplitude=mean * contrast, cycles_u=2.0 * math.cos(0.3), cycles_v=2.0 * math.sin(0.3),
                   deg_per_unit_u=surface_deg_per_unit(12.0), deg_per_unit_v=surface_deg_per_unit(12.0),
                   phase_cycles=0.1, window=WindowKind.GAUSSIAN, window_1=1.5)


def _achieved_contrast(luminance: np.ndarray, grating: Grating, x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """(mean cd/m², Michelson contrast) of a Gabor's luminance image: least squares of
    L = m + a w sin(2 pi c) + b w cos(2 pi c) over the pixels within 5 sigma (c, w: the Gabor's own phase and window
    at each pixel's surface point), contrast sqrt(a² + b²) / m."""
    cycles = x * grating.cycles_u + y * grating.cycles_v + grating.phase_cycles
    w = grating.envelope(x, y)
    use = np.hypot(x, y) < 5 * grating.window_1
    design = np.stack([np.ones(use.sum()), (w * np.sin(2 * np.pi * cycles))[use],
                       (w * np.cos(2 * np.pi * cycles))[use]], axis=1)
    (m, a, b), *_ = np.linalg.lstsq(design, luminance[use], rcond=None)
    return float(m), float(math.hypot(a, b) / m)


def test_a_one_percent_gabor_has_its_contrast_after_quantisation(gl_context, known_display):
    """1 % Michelson contrast on 40 cd/m² (an amplitude of 0.73 codes on this display): the codes read back, turned
    into luminance through the TRUE transfer (not the fitted one), give a contrast within 0.05 percentage points of
    1 %, in one frame (spatial dither averaged by the fit over the Gabor's pixels) and over 8 frames (temporal
    dither averaged per pixel first), and a mean within 0.1 %. Rounding without the dither misses by far more."""
    truth, transfer = known_display
    output = Output(transfer)
    gabor = _gabor(output, 0.01)
    prim = placed_primitive(Shape.RECT, 1.0, 12.0, 12.0, gabor, origin_m=RIGHT_CENTRE_M, name="gabor")
    camera = _camera()
    x, y = _surface_deg(camera, prim)
    scene = Scene((prim,), background=(gabor.mean,) * 3, output=output.scene_output())
    frames = []
    with Renderer(scene, NO_REUSE, ctx=gl_context) as renderer:
        for _ in range(8):
            renderer.render(camera)
            frames.append(truth(renderer.image_uint8()[..., 0]))
        linear = renderer.linear_image()[..., 0]
    assert np.abs(linear * transfer.peak_cd_m2 - (gabor.value(x, y) * transfer.peak_cd_m2)).max() < 1e-3
    one_mean, one = _achieved_contrast(frames[0], gabor, x, y)
    many_mean, many = _achieved_contrast(np.mean(frames, axis=0), gabor, x, y)
    assert abs(one - 0.01) < 0.0005 and abs(many - 0.01) < 0.0005, (one, many)
    assert one_mean == pytest.approx(40.0, rel=1e-3) and many_mean == pytest.approx(40.0, rel=1e-3)
    rounded = Scene((prim,), background=(gabor.mean,) * 3,
                    output=OutputTransfer(scene.output.table, key="rounded", dither=False))
    with Renderer(rounded, ctx=gl_context) as renderer:
        renderer.render(camera)
        _, plain = _achieved_contrast(truth(renderer.image_uint8()[..., 0]), gabor, x, y)
    assert abs(plain - 0.01) > 0.0005, plain  # rounding alone misses the 0.05 pp bound (measured 0.919 %)
