"""The two-pass adaptive sampler (with and without screen-box culling) gives the same image
as the single-pass one, and its screen
boxes are conservative (every point of a primitive projects inside its box)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from psyop.rendering import Renderer, RenderSettings, Scene
from psyop.rendering.builders import detection_stimulus, ordinal_stimulus
from psyop.rendering.camera_math import crop_camera, project_points_px
from psyop.rendering.measure import RIGHT_CENTRE_M, right_eye_camera
from psyop.rendering.screen_bounds import UNBOUNDED_PX, screen_bounds_px


def _scenes() -> list[Scene]:
    back, front = detection_stimulus(2.0, 0.5, origin_m=RIGHT_CENTRE_M)
    rear, near = ordinal_stimulus(0.5, 2.5, "left", origin_m=RIGHT_CENTRE_M, amplitude_deg=1.0, cycles=3.0)
    return [Scene((back, front)), Scene((rear, near))]


def test_two_pass_image_equals_single_pass_and_marks_the_same_pixels(gl_context):
    full = right_eye_camera(12.0, 5.0, "ocular")
    for scene in _scenes():
        c = project_points_px(full, [scene.primitives[-1].centre_m])[0]
        cam = crop_camera(full, int(c[0]) - 40, int(c[1]) - 40, 80, 80)
        images, edges = [], []
        for two_pass, cull in ((False, False), (True, False), (True, True)):
            with Renderer(scene, RenderSettings(adaptive_two_pass=two_pass, adaptive_cull=cull),
                          ctx=gl_context) as renderer:
                renderer.render(cam)
                images.append(renderer.image())
                edges.append(renderer.edge_pixel_count())
        assert edges[0] == edges[1] == edges[2] > 0
        assert np.array_equal(images[0], images[1]) and np.array_equal(images[0], images[2])


@settings(max_examples=25, deadline=None)
@given(az=st.floats(-30, 30), el=st.floats(-30, 30), mode=st.sampled_from(["ocular", "conventional"]))
def test_screen_boxes_contain_every_point_of_every_primitive(az, el, mode):
    cam = right_eye_camera(az, el, mode)
    scene = Scene(_scenes()[0].primitives + _scenes()[1].primitives)
    cop = np.asarray(cam.centre_of_projection_m, dtype=np.float64)
    prims = scene.primitives
    boxes = screen_bounds_px(np.array([p.centre_m for p in prims]) - cop, np.array([p.half_u_m for p in prims]),
                             np.array([p.half_v_m for p in prims]), cam.pixel_to_ray, cam.width_px, cam.height_px)
    angles = np.linspace(0.0, 2.0 * math.pi, 97)
    radii = np.array([0.0, 0.5, 1.0])
    for p, box in zip(prims, boxes):
        a = (radii[:, None] * np.cos(angles)).ravel()
        b = (radii[:, None] * np.sin(angles)).ravel()
        pts = np.asarray(p.centre_m) + a[:, None] * np.asarray(p.half_u_m) + b[:, None] * np.asarray(p.half_v_m)
        xy = project_points_px(cam, pts)
        if np.all(np.abs(box) < UNBOUNDED_PX):
            assert np.all(np.isfinite(xy))
            assert np.all(xy[:, 0] >= box[0] - 1e-6) and np.all(xy[:, 0] <= box[2] + 1e-6)
            assert np.all(xy[:, 1] >= box[1] - 1e-6) and np.all(xy[:, 1] <= box[3] + 1e-6)
        # a tight box: the rim's own extent spans most of it
        if np.all(np.abs(box) < UNBOUNDED_PX):
            assert (xy[:, 0].max() - xy[:, 0].min()) >= 0.5 * (box[2] - box[0])


def test_a_primitive_behind_the_centre_of_projection_is_unbounded():
    cam = right_eye_camera(0.0, 0.0, "ocular")
    behind = np.array([[0.0, 0.0, 1.0]])
    box = screen_bounds_px(behind, np.array([[0.1, 0, 0]]), np.array([[0, 0.1, 0]]), cam.pixel_to_ray,
                           cam.width_px, cam.height_px)
    assert np.all(box[0, :2] <= -UNBOUNDED_PX) and np.all(box[0, 2:] >= UNBOUNDED_PX)


def test_edge_block_count_groups_edge_pixels_into_aligned_blocks(gl_context):
    back, front = detection_stimulus(2.0, 0.5, origin_m=RIGHT_CENTRE_M)
    full = right_eye_camera(12.0, 5.0, "ocular")
    c = project_points_px(full, [back.centre_m])[0]
    cam = crop_camera(full, int(c[0]) - 30, int(c[1]) - 30, 61, 58)  # sizes not multiples of 4
    with Renderer(Scene((back, front)), ctx=gl_context) as renderer:
        renderer.render(cam)
        mask = renderer.edge_mask()
        n_px, n_blocks = renderer.edge_pixel_count(), renderer.edge_block_count()
        assert renderer.edge_block_count(block_px=1) == n_px == int(mask.sum()) > 0
    assert n_px / 16 <= n_blocks <= n_px
    # direct count over window-coordinate blocks (rows counted from the bottom)
    rows, cols = np.nonzero(mask[::-1])
    assert n_blocks == len({(r // 4, q // 4) for r, q in zip(rows, cols)})
