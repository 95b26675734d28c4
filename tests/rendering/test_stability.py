"""Numerical stability: extreme clip ranges and depths, gaze to the display edge, bad gaze."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from psyop.optics.camera import make_eye_camera
from psyop.optics.display import symmetric_profile
from psyop.rendering import Renderer, Scene, Solid
from psyop.rendering.builders import frontoparallel_disc, frontoparallel_rect
from psyop.rendering.measure import FIXTURE_IPD_M as IPD_M, NC_M
from psyop.rendering.measure import RIGHT_CENTRE_M as RIGHT_EYE_CENTRE_M

# The Vive Pro's full field of view at a tenth of its resolution: every eccentricity up to the
# display edge is rendered, cheaply.
SMALL_VIVE = symmetric_profile("small_vive", 144, 160, 90.0, 110.0)

EXTREME_SCENE = Scene(
    (
        frontoparallel_disc(1.2e-2, 30.0, Solid((1.0, 0.0, 0.0)), -20.0, 10.0, RIGHT_EYE_CENTRE_M, name="very_near"),
        frontoparallel_disc(0.5, 10.0, Solid((0.0, 1.0, 0.0)), 30.0, -30.0, RIGHT_EYE_CENTRE_M, name="mid"),
        frontoparallel_disc(5e3, 20.0, Solid((0.0, 0.0, 1.0)), -40.0, -35.0, RIGHT_EYE_CENTRE_M, name="very_far"),
        frontoparallel_rect(9e3, 150.0, 150.0, Solid((0.2, 0.2, 0.2)), origin_m=RIGHT_EYE_CENTRE_M, name="wall"),
    ),
    background=(0.5, 0.5, 0.5),
)


def _camera(fixation, mode="ocular"):
    return make_eye_camera(SMALL_VIVE, "right", fixation, IPD_M, NC_M, mode, near_m=1e-3, far_m=1e4)


def _fixation(az_deg: float, el_deg: float, distance_m: float) -> np.ndarray:
    d = np.array([math.sin(math.radians(az_deg)) * math.cos(math.radians(el_deg)), math.sin(math.radians(el_deg)),
                  -math.cos(math.radians(az_deg)) * math.cos(math.radians(el_deg))])
    return RIGHT_EYE_CENTRE_M + distance_m * d


def test_extreme_depths_render_finite_and_every_depth_is_visible(gl_context):
    with Renderer(EXTREME_SCENE, ctx=gl_context) as renderer:
        renderer.render(_camera(_fixation(0.0, 0.0, 1.0)))
        img = renderer.image()
    assert np.all(np.isfinite(img))
    # each primitive from 12 mm (4 mm beyond the nodal point) to 9 km contributes pixels of its own colour
    for colour in ((1, 0, 0), (0, 1, 0), (0, 0, 1), (0.2, 0.2, 0.2)):
        assert np.sum(np.all(np.abs(img - np.array(colour, dtype=np.float32)) < 1e-3, axis=-1)) > 5, colour


@settings(max_examples=25)
@given(
    az=st.floats(-60.0, 60.0),
    el=st.floats(-60.0, 60.0),
    distance=st.one_of(st.floats(1e-4, 1e5), st.just(0.0), st.just(math.inf), st.just(math.nan), st.just(-1.0)),
    mode=st.sampled_from(["conventional", "ocular", "reversed"]),
)
def test_any_gaze_gives_finite_pixels_and_never_raises(gl_context, az, el, distance, mode):
    fixation = _fixation(az, el, distance) if math.isfinite(distance) else np.array([distance, az, el])
    with Renderer(EXTREME_SCENE, ctx=gl_context) as renderer:
        result = renderer.render(_camera(fixation, mode))
        img = renderer.image()
    assert result.rendered
    assert np.all(np.isfinite(img)) and img.min() >= 0.0 and img.max() <= 1.0


class _BadCamera:
    """A camera as a broken upstream might deliver it: NaN everywhere, flagged invalid."""

    eye = "right"
    mode = "ocular"
    valid = False
    width_px = SMALL_VIVE.width_px
    height_px = SMALL_VIVE.height_px
    centre_of_projection_m = np.full(3, np.nan)
    pixel_to_ray = np.full((3, 3), np.nan)
    projection = np.full((4, 4), np.nan)
    view = np.full((4, 4), np.nan)


def test_invalid_cameras_keep_the_last_valid_one(gl_context):
    with Renderer(EXTREME_SCENE, ctx=gl_context) as renderer:
        first = renderer.render(_BadCamera())  # nothing valid yet: background only
        assert not first.camera_usable and first.camera_used is None
        assert np.allclose(renderer.image(), 0.5)
        good = _camera(_fixation(20.0, 5.0, 0.7))
        renderer.render(good)
        reference = renderer.image()
        again = renderer.render(_BadCamera())
        assert again.camera_used is good
        assert np.array_equal(renderer.image(), reference)
        assert renderer.stats.invalid_cameras == 2
        assert renderer.stats.frames_requested == 3
