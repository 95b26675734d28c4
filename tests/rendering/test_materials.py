"""Materials: image orientation, noise statistics, grid lines, scene validation."""

from __future__ import annotations

import numpy as np
import pytest

from psyop.rendering import GridMaterial, ImageTexture, NoiseKind, NoiseTexture, Primitive, Renderer, Scene, Shape
from psyop.rendering.builders import frontoparallel_rect, target_field
from psyop.rendering.camera_math import crop_camera, project_points_px
from psyop.rendering.measure import RIGHT_CENTRE_M, right_eye_camera
from psyop.rendering.textures import noise_pixels


def test_image_texture_keeps_its_orientation(gl_context):
    image = np.zeros((2, 2, 3))
    image[0, 0] = (1, 0, 0)  # top-left red
    image[0, 1] = (0, 1, 0)  # top-right green
    image[1, 0] = (0, 0, 1)  # bottom-left blue
    image[1, 1] = (1, 1, 1)  # bottom-right white
    quad = frontoparallel_rect(1.0, 6.0, 6.0, ImageTexture(image, key="quadrants"), origin_m=RIGHT_CENTRE_M)
    full = right_eye_camera(0.0, 0.0, "conventional")
    c = project_points_px(full, [quad.centre_m])[0]
    camera = crop_camera(full, int(c[0]) - 20, int(c[1]) - 20, 40, 40)
    with Renderer(Scene((quad,)), ctx=gl_context) as renderer:
        renderer.render(camera)
        img = renderer.image()
    assert np.allclose(img[12, 12], (1, 0, 0)) and np.allclose(img[12, 28], (0, 1, 0))
    assert np.allclose(img[28, 12], (0, 0, 1)) and np.allclose(img[28, 28], (1, 1, 1))


@pytest.mark.parametrize("kind", [NoiseKind.WHITE, NoiseKind.PINK])
def test_noise_has_requested_mean_and_spectrum(kind):
    pixels = noise_pixels(NoiseTexture(kind, seed=3, size_px=128, mean=0.5, contrast=0.2))[..., 0]
    assert pixels.mean() == pytest.approx(0.5, abs=0.01)
    assert pixels.std() == pytest.approx(0.1, rel=0.05)
    power = np.abs(np.fft.fft2(pixels - pixels.mean())) ** 2
    low, high = power[1:4, 1:4].mean(), power[40:60, 40:60].mean()
    if kind is NoiseKind.PINK:
        assert low > 100 * high  # 1/f: power falls ~ f^-2
    else:
        assert 0.2 < low / high < 5.0  # white: flat


def test_grid_lines_are_drawn_and_filtered(gl_context):
    grid = GridMaterial(background=(0, 0, 0), line_colour=(1, 1, 1), lines_per_side=8, line_width_fraction=0.1)
    quad = frontoparallel_rect(1.0, 20.0, 20.0, grid, origin_m=RIGHT_CENTRE_M)
    full = right_eye_camera(0.0, 0.0, "conventional")
    c = project_points_px(full, [quad.centre_m])[0]
    camera = crop_camera(full, int(c[0]) - 64, int(c[1]) - 64, 128, 128)
    with Renderer(Scene((quad,)), ctx=gl_context) as renderer:
        renderer.render(camera)
        img = renderer.image()[..., 0]
    # line share of the area: 1 - (1 - 0.1)^2 = 19 %; box filtering keeps the mean, not just 0/1
    assert img.mean() == pytest.approx(0.19, abs=0.03)
    assert np.any((img > 0.05) & (img < 0.95))


def test_target_field_is_deterministic_and_non_overlapping():
    a = target_field(seed=4, n_targets=15)
    b = target_field(seed=4, n_targets=15)
    assert a == b and len(a) == 15
    dirs = np.array([np.array(p.centre_m) / np.linalg.norm(p.centre_m) for p in a])
    ang = np.degrees(np.arccos(np.clip(dirs @ dirs.T, -1, 1)))
    np.fill_diagonal(ang, 180.0)
    assert ang.min() > 2.6  # each subtends 2.6 deg: no two overlap


def test_primitive_validation():
    with pytest.raises(ValueError, match="orthogonal"):
        Primitive(Shape.RECT, (0, 0, -1), (1, 0, 0), (1, 1, 0), GridMaterial())
    with pytest.raises(ValueError, match="finite"):
        Primitive(Shape.DISC, (0, np.nan, -1), (1, 0, 0), (0, 1, 0), GridMaterial())
