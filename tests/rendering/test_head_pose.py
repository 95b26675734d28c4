"""A world-fixed stimulus seen from a tracked head: the scene moves in the image exactly as
its world points project from the moved eye (head pose applied as p_head = R^T (p - t))."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from psyop.optics import VIVE_PRO, make_eye_camera, project_to_pixels
from psyop.rendering import Renderer, RenderSettings, Scene, Solid
from psyop.rendering.builders import frontoparallel_disc
from psyop.rendering.camera_math import crop_camera
from psyop.rendering.transform import IDENTITY_WXYZ, rotation_matrix, scene_in_head

IPD_M, NC_M = 0.064, 0.0076916
EYE_CENTRE = np.array([IPD_M / 2, 0.0, 0.0])


def _wxyz(rotation: Rotation) -> tuple[float, float, float, float]:
    x, y, z, w = rotation.as_quat()
    return (w, x, y, z)


def test_rotation_matrix_matches_scipy() -> None:
    rng = np.random.default_rng(0)
    for q in Rotation.random(20, random_state=rng):
        np.testing.assert_allclose(rotation_matrix(_wxyz(q)), q.as_matrix(), atol=1e-12)


def test_identity_pose_returns_the_same_scene_object() -> None:
    scene = Scene((frontoparallel_disc(1.0, 2.0, Solid((1, 0, 0)), origin_m=EYE_CENTRE),))
    assert scene_in_head(scene, (0.0, 0.0, 0.0), IDENTITY_WXYZ) is scene


@pytest.mark.parametrize("yaw_deg, shift_m", [(3.0, (0.0, 0.0, 0.0)), (0.0, (0.01, -0.005, 0.0)), (-2.0, (0.004, 0.0, 0.01))])
def test_head_pose_moves_the_disc_where_the_world_point_projects(yaw_deg: float, shift_m: tuple) -> None:
    world_disc = frontoparallel_disc(0.5, 2.0, Solid((1.0, 0.0, 0.0)), origin_m=EYE_CENTRE, name="disc")
    scene = Scene((world_disc,), background=(0.0, 0.0, 0.0))
    q = _wxyz(Rotation.from_euler("y", yaw_deg, degrees=True))
    moved = scene_in_head(scene, shift_m, q)
    # the exact prediction: the world centre in the moved head's coordinates, projected
    centre_head = rotation_matrix(q).T @ (np.asarray(world_disc.centre_m) - np.asarray(shift_m))
    camera = make_eye_camera(VIVE_PRO, "right", (EYE_CENTRE[0], 0.0, -1.0), IPD_M, NC_M, "conventional")
    expected_px = project_to_pixels(camera, centre_head[None, :])[0]
    x0, y0 = int(expected_px[0]) - 40, int(expected_px[1]) - 40
    window = crop_camera(camera, x0, y0, 80, 80)
    with Renderer(moved, settings=RenderSettings()) as renderer:
        renderer.render(window)
        red = renderer.image("right")[..., 0].astype(np.float64)
    ys, xs = np.mgrid[0:80, 0:80] + 0.5
    measured_px = np.array([(red * xs).sum() / red.sum() + x0, (red * ys).sum() / red.sum() + y0])
    # a rotated disc projects to a near-ellipse whose area centroid sits within a small fraction
    # of a pixel of its centre's projection at these angles
    assert np.linalg.norm(measured_px - expected_px) < 0.05
    # and the motion is real: the still head puts the disc elsewhere
    still_px = project_to_pixels(camera, np.asarray(world_disc.centre_m)[None, :])[0]
    assert np.linalg.norm(still_px - expected_px) > 5.0
    assert math.isfinite(red.sum()) and red.sum() > 100
