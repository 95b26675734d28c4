"""Frame reuse: the shift bound really bounds every scene point's image motion, and skipped
frames are counted and leave the image untouched."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from psyop.optics.display import VIVE_PRO, symmetric_profile
from psyop.rendering import Renderer, Scene
from psyop.rendering.builders import detection_stimulus, target_field
from psyop.rendering.camera_math import crop_camera, project_points_px
from psyop.rendering.reuse import decide_reuse
from psyop.rendering.measure import RIGHT_CENTRE_M as RIGHT_EYE_CENTRE_M
from psyop.rendering.measure import right_eye_camera as gaze_camera

NEAR_DISPLAY = symmetric_profile("near_display", 1440, 1600, 90.0, 110.0, d_m=1.5)
SCENE = Scene(target_field(seed=3, n_targets=12, origin_m=RIGHT_EYE_CENTRE_M) +
              detection_stimulus(3.0, 1.0, origin_m=RIGHT_EYE_CENTRE_M))


def _scene_points(scene: Scene) -> np.ndarray:
    ang = np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)
    pts = [np.array(p.centre_m) + np.cos(a) * np.array(p.half_u_m) + np.sin(a) * np.array(p.half_v_m)
           for p in scene.primitives for a in ang]
    return np.array(pts)


def _actual_shift_px(cam_a, cam_b, points: np.ndarray) -> float:
    pa, pb = project_points_px(cam_a, points), project_points_px(cam_b, points)
    ok = np.all(np.isfinite(pa) & np.isfinite(pb), axis=-1)
    return float(np.max(np.linalg.norm(pa[ok] - pb[ok], axis=-1)))


@settings(max_examples=40)
@given(
    az=st.floats(-30.0, 30.0), el=st.floats(-30.0, 30.0),
    daz=st.floats(-0.2, 0.2), del_=st.floats(-0.2, 0.2),
    finite_display=st.booleans(),
)
def test_bound_is_an_upper_bound_on_every_points_shift(az, el, daz, del_, finite_display):
    display = NEAR_DISPLAY if finite_display else VIVE_PRO
    a = gaze_camera(az, el, "ocular", display=display)
    b = gaze_camera(az + daz, el + del_, "ocular", display=display)
    decision = decide_reuse(a, b, SCENE.depth_range_m(a.centre_of_projection_m), tolerance_px=0.01)
    actual = _actual_shift_px(a, b, _scene_points(SCENE))
    assert actual <= decision.bound_px * (1 + 1e-9) + 1e-12
    if decision.skip:
        assert actual <= 0.01


def test_bound_is_not_wildly_loose():
    a = gaze_camera(10.0, 0.0, "ocular")
    b = gaze_camera(10.05, 0.0, "ocular")
    decision = decide_reuse(a, b, SCENE.depth_range_m(a.centre_of_projection_m))
    actual = _actual_shift_px(a, b, _scene_points(SCENE))
    assert 0.0 < actual <= decision.bound_px < 20.0 * actual


def test_renderer_skips_tiny_gaze_changes_and_counts_them(gl_context):
    back, front = detection_stimulus(1.0, 0.5, origin_m=RIGHT_EYE_CENTRE_M)
    scene = Scene((back, front))

    c = project_points_px(gaze_camera(16.0, 0.0, "ocular"), [back.centre_m])[0]

    def cam(az):  # one fixed window around the stimulus
        return crop_camera(gaze_camera(az, 0.0, "ocular"), int(c[0]) - 20, int(c[1]) - 20, 40, 40)

    with Renderer(scene, ctx=gl_context) as renderer:
        first = renderer.render(cam(16.0))
        image = renderer.image()
        tiny = renderer.render(cam(16.0 + 1e-4))  # NC * 1e-4 deg ~ 13 nm of travel
        assert first.rendered and not tiny.rendered
        assert tiny.reuse.bound_px <= 0.01 and tiny.reuse.bound_px > 0.0
        assert np.array_equal(renderer.image(), image)
        big = renderer.render(cam(20.0))
        assert big.rendered and big.reuse.bound_px > 0.01
        assert not np.array_equal(renderer.image(), image)
        moved_window = renderer.render(crop_camera(gaze_camera(20.0, 0.0, "ocular"), int(c[0]) - 19,
                                                   int(c[1]) - 20, 40, 40))
        assert moved_window.rendered and moved_window.reuse.reason == "pixel grid moved"
        # a mode change moves the centre of projection by ~NC: always rendered
        conv = renderer.render(crop_camera(gaze_camera(20.0, 0.0, "conventional"), int(c[0]) - 20,
                                           int(c[1]) - 20, 40, 40))
        assert conv.rendered
        assert renderer.stats.frames_skipped == 1
        assert renderer.stats.frames_rendered == 4
        assert math.isclose(renderer.stats.largest_skipped_bound_px, tiny.reuse.bound_px)


def test_stereo_renders_each_eye_separately(gl_context):
    back, front = detection_stimulus(2.0, 1.0, origin_m=(0.0, 0.0, 0.0))
    with Renderer(Scene((back, front)), ctx=gl_context) as renderer:
        right = crop_camera(gaze_camera(0.0, 0.0, "ocular", eye="right"), 620, 700, 200, 200)
        left = crop_camera(gaze_camera(0.0, 0.0, "ocular", eye="left"), 620, 700, 200, 200)
        renderer.render(right)
        renderer.render(left)
        img_r, img_l = renderer.image("right"), renderer.image("left")
    # the discs sit between the eyes: each eye sees them displaced towards the nose
    col_r = np.nonzero(img_r[..., 0].max(axis=0) > 0.55)[0].mean()
    col_l = np.nonzero(img_l[..., 0].max(axis=0) > 0.55)[0].mean()
    assert col_r < col_l - 5


def test_equal_scene_keeps_reuse_and_a_changed_scene_renders(gl_context):
    back, front = detection_stimulus(1.0, 0.5, origin_m=RIGHT_EYE_CENTRE_M)
    camera = crop_camera(gaze_camera(16.0, 0.0, "ocular"), 700, 780, 40, 40)
    with Renderer(Scene((back, front)), ctx=gl_context) as renderer:
        renderer.render(camera)
        renderer.set_scene(Scene(detection_stimulus(1.0, 0.5, origin_m=RIGHT_EYE_CENTRE_M)))  # equal, new object
        assert not renderer.render(camera).rendered
        renderer.set_scene(Scene(detection_stimulus(1.0, 0.75, origin_m=RIGHT_EYE_CENTRE_M)))
        assert renderer.render(camera).rendered
        assert renderer.stats.frames_skipped == 1
