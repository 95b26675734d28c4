"""The mesh pass (psyop.rendering.mesh_pass) against exact geometry: a mesh quad/disc equals the analytic
primitive of the same geometry within the anti-aliasing error, meshes and primitives occlude each other
as the exact ray-triangle path says (psyop.rendering.mesh_exact, an independent numpy path), the ocular
parallax of a mesh vertex is the optics formula, and a texel lands where its texture coordinate says."""

from __future__ import annotations

import math

import numpy as np
import pytest

from psyop.optics.camera import make_eye_camera
from psyop.optics.display import VIVE_PRO
from psyop.optics.parallax import ocular_parallax_exact_rad
from psyop.rendering import Renderer, RenderSettings, Scene, Solid
from psyop.rendering.builders import direction_from_angles, frontoparallel_disc
from psyop.rendering.camera_math import crop_camera, pixel_rays, project_points_px
from psyop.rendering.exact_coverage import projected_area_px
from psyop.rendering.measure import FIXTURE_IPD_M as IPD_M, NC_M, RIGHT_CENTRE_M, right_eye_camera
from psyop.rendering.mesh_exact import exact_coverage
from psyop.rendering.mesh_scene import MeshInstance, model_matrix
from psyop.rendering.scene import Primitive, Shape
from psyop.rendering.transform import scene_in_head
from tests.rendering.mesh_helpers import asset, checker_texture, disc_part, quad_part

RED = (1.0, 0.0, 0.0, 1.0)


def _window(camera, point_m, half_px: int = 40):
    c = project_points_px(camera, [point_m])[0]
    return crop_camera(camera, int(c[0]) - half_px, int(c[1]) - half_px, 2 * half_px, 2 * half_px)


def _render(scene, camera, ctx, settings=None):
    with Renderer(scene, settings or RenderSettings(reuse_tolerance_px=None), ctx=ctx) as r:
        r.render(camera)
        return r.image()


def _red(img):
    return img[..., 0].astype(np.float64) - img[..., 1]


@pytest.mark.parametrize("mode", ["conventional", "ocular", "reversed"])
def test_mesh_quad_and_disc_equal_the_analytic_primitives(gl_context, mode):
    centre = RIGHT_CENTRE_M + np.array([0.01, 0.02, -1.0])
    quad = Primitive(Shape.RECT, tuple(centre), (0.02, 0, 0), (0, 0.015, 0), Solid((1, 0, 0)), name="q")
    disc = Primitive(Shape.DISC, tuple(centre), (0.02, 0, 0), (0, 0.02, 0), Solid((1, 0, 0)), name="d")
    cam = _window(right_eye_camera(8.0, 4.0, mode), centre)
    model = tuple(model_matrix(centre, (0, 0, 0), 1.0).reshape(-1))
    for prim, mesh_part in ((quad, quad_part(0.02, 0.015, colour=RED)), (disc, disc_part(0.02, 512, colour=RED))):
        analytic = _render(Scene((prim,), background=(0, 0, 0)), cam, gl_context)
        mesh = _render(Scene((), background=(0, 0, 0), meshes=(MeshInstance(asset(mesh_part), model, "m"),)), cam,
                       gl_context)
        exact = projected_area_px(cam, prim)
        # areas: MSAA 4 vs the analytic sampler, both within 1 % of the exact projected area
        assert abs(_red(mesh).sum() - exact) / exact < 0.01
        assert abs(_red(analytic).sum() - exact) / exact < 0.01
        diff = np.abs(_red(mesh) - _red(analytic))
        def partial(x: np.ndarray) -> np.ndarray:
            return (x > 1e-6) & (x < 1 - 1e-6)

        assert diff.max() <= 0.5 + 1e-6  # edge pixels only: 4 MSAA samples vs the analytic grid
        assert not np.any((diff > 1e-6) & ~partial(_red(analytic)) & ~partial(_red(mesh)))


def test_mixed_scene_occludes_like_exact_ray_casting(gl_context):
    cam = _window(right_eye_camera(5.0, 0.0, "ocular"), RIGHT_CENTRE_M + np.array([0.0, 0.0, -1.0]), 48)
    mid = MeshInstance(asset(quad_part(0.03, 0.03, colour=(0.0, 1.0, 0.0, 1.0))),
                       tuple(model_matrix(RIGHT_CENTRE_M + [0.0, 0.0, -1.0], (0, 0, 0), 1.0).reshape(-1)), "mesh_mid")
    far = Primitive(Shape.DISC, tuple(RIGHT_CENTRE_M + [0.02, 0.0, -2.0]), (0.05, 0, 0), (0, 0.05, 0),
                    Solid((1, 0, 0)), name="far_disc")
    near = Primitive(Shape.RECT, tuple(RIGHT_CENTRE_M + [-0.008, 0.004, -0.5]), (0.006, 0, 0), (0, 0.004, 0),
                     Solid((0, 0, 1)), name="near_rect")
    scene = Scene((far, near), background=(0, 0, 0), meshes=(mid,))
    img = _render(scene, cam, gl_context)
    exact = exact_coverage(cam, scene, samples_per_axis=4)
    for name, channel in (("far_disc", 0), ("mesh_mid", 1), ("near_rect", 2)):
        measured = img[..., channel].astype(np.float64).sum()
        want = exact[name].sum()
        assert want > 20
        assert abs(measured - want) / want < 0.02, (name, measured, want)
        # per pixel: only edge pixels differ (anti-aliasing), by at most one pixel's share
        inside = exact[name] == 1.0  # all 16 exact samples: the pixel is (nearly) covered
        assert np.all(img[..., channel][inside] > 0.95), (name, img[..., channel][inside].min())


def test_mesh_scene_in_head_moves_the_mesh_like_a_primitive(gl_context):
    """A tracked head moves the viewer through a world-fixed mesh exactly as through a primitive."""
    centre = np.array([0.05, 0.0, -1.2])
    prim = Primitive(Shape.RECT, tuple(centre), (0.03, 0, 0), (0, 0.03, 0), Solid((1, 0, 0)), name="p")
    mesh = MeshInstance(asset(quad_part(0.03, 0.03, colour=RED)), tuple(model_matrix(centre, (0, 0, 0), 1.0).reshape(-1)))
    pose = ((0.02, -0.01, 0.1), (math.cos(0.05), 0.0, math.sin(0.05), 0.0))
    cam = right_eye_camera(3.0, 1.0, "ocular")
    moved_prim = scene_in_head(Scene((prim,), background=(0, 0, 0)), *pose)
    moved_mesh = scene_in_head(Scene((), background=(0, 0, 0), meshes=(mesh,)), *pose)
    cam = _window(cam, moved_prim.primitives[0].centre_m, 48)
    a, m = _red(_render(moved_prim, cam, gl_context)), _red(_render(moved_mesh, cam, gl_context))
    assert abs(a.sum() - m.sum()) / a.sum() < 0.01
    assert np.abs(a - m).max() <= 0.5 + 1e-6


def _centroid_direction(cam, img):
    w = _red(img)
    ys, xs = np.mgrid[0:w.shape[0], 0:w.shape[1]]
    xy = np.array([[(w * (xs + 0.5)).sum() / w.sum(), (w * (ys + 0.5)).sum() / w.sum()]])
    return pixel_rays(cam, xy)[0]


@pytest.mark.parametrize("ecc_deg", [10.0, 20.0])
def test_ocular_parallax_of_a_mesh_vertex_is_the_optics_formula(gl_context, ecc_deg):
    near_D, far_D = 2.0, 0.5
    axis = RIGHT_CENTRE_M
    fixation = RIGHT_CENTRE_M + direction_from_angles(ecc_deg, 0.0) * 0.5
    full = make_eye_camera(VIVE_PRO, "right", fixation, IPD_M, NC_M, "ocular")
    cam = _window(full, axis + [0.0, 0.0, -1.0 / near_D], 40)
    # the near point is a tiny eye-facing mesh disc on the eye's straight-ahead axis; the far one an analytic disc
    radius = 0.012 / near_D  # ~30 px across: MSAA's 4-sample centroid error is far below the tolerance
    near = MeshInstance(asset(disc_part(radius, 256, colour=RED)),
                        tuple(model_matrix(axis + [0.0, 0.0, -1.0 / near_D], (0, 0, 0), 1.0).reshape(-1)))
    far = frontoparallel_disc(1.0 / far_D, math.degrees(2 * math.atan(radius * near_D)), Solid((1, 0, 0)),
                              origin_m=axis)
    d_near = _centroid_direction(cam, _render(Scene((), background=(0, 0, 0), meshes=(near,)), cam, gl_context))
    d_far = _centroid_direction(cam, _render(Scene((far,), background=(0, 0, 0)), cam, gl_context))
    measured = math.atan2(np.linalg.norm(np.cross(d_near, d_far)), float(d_near @ d_far))
    want = float(ocular_parallax_exact_rad(ecc_deg, near_D, far_D, NC_M))
    px_rad = math.radians(VIVE_PRO.horizontal_fov_deg) / VIVE_PRO.width_px
    assert abs(measured - want) < 0.03 * px_rad + 0.005 * want, (measured, want)


def test_a_texel_lands_where_its_texture_coordinate_says(gl_context):
    tex = checker_texture(4)
    centre = RIGHT_CENTRE_M + np.array([0.0, 0.0, -0.8])
    hw, hh = 0.04, 0.03
    mesh = MeshInstance(asset(quad_part(hw, hh, texture=tex)), tuple(model_matrix(centre, (0, 0, 0), 1.0).reshape(-1)))
    cam = _window(right_eye_camera(6.0, -3.0, "ocular"), centre, 60)
    img = _render(Scene((), background=(0, 0, 0), meshes=(mesh,)), cam, gl_context)
    for row in range(4):
        for col in range(4):
            u, v = (col + 0.5) / 4, (row + 0.5) / 4
            point = centre + [-hw + 2 * hw * u, hh - 2 * hh * v, 0.0]
            x, y = project_points_px(cam, [point])[0]
            pixel = img[int(y), int(x)]
            assert pixel[0] == pytest.approx((col + 0.5) / 4, abs=1e-6)
            assert pixel[1] == pytest.approx((row + 0.5) / 4, abs=1e-6)


def test_parts_outside_the_frustum_are_skipped_and_blend_is_drawn_over(gl_context):
    from psyop.mesh.asset import AlphaMode
    from psyop.rendering.mesh_pass import MeshPass

    behind = quad_part(0.02, 0.02, colour=RED)
    behind = type(behind)(**{**behind.__dict__, "positions": behind.positions + [0, 0, 3.0],
                             "bbox_min": behind.bbox_min + [0, 0, 3.0], "bbox_max": behind.bbox_max + [0, 0, 3.0]})
    glass = quad_part(0.01, 0.01, colour=(0.0, 0.0, 1.0, 0.5), alpha_mode=AlphaMode.BLEND)
    glass = type(glass)(**{**glass.__dict__, "positions": glass.positions + [0, 0, 0.1],
                           "bbox_min": glass.bbox_min + [0, 0, 0.1], "bbox_max": glass.bbox_max + [0, 0, 0.1]})
    front = quad_part(0.02, 0.02, colour=RED)
    centre = RIGHT_CENTRE_M + np.array([0.0, 0.0, -1.0])
    inst = MeshInstance(asset(glass, front, behind), tuple(model_matrix(centre, (0, 0, 0), 1.0).reshape(-1)))
    cam = _window(right_eye_camera(0.0, 0.0, "conventional"), centre, 30)
    mp = MeshPass(gl_context)
    try:
        target = mp.target(cam.width_px, cam.height_px)
        assert mp.draw(target, cam, (inst,)) == 2  # the part 3 m behind the viewer is culled
        target.release()
    finally:
        mp.release()
    img = _render(Scene((), background=(0, 0, 0), meshes=(inst,)), cam, gl_context)
    x, y = project_points_px(cam, [centre])[0]
    assert img[int(y), int(x)] == pytest.approx([0.5, 0.0, 0.5], abs=1e-6)  # half blue over red


def test_scenes_without_meshes_run_the_analytic_programs_unchanged(gl_context):
    """A renderer that drew a mesh scene draws a mesh-free scene exactly as a fresh renderer does."""
    disc = frontoparallel_disc(1.0, 2.0, Solid((1, 0, 0)), origin_m=RIGHT_CENTRE_M)
    cam = _window(right_eye_camera(4.0, 2.0, "ocular"), disc.centre_m)
    fresh = _render(Scene((disc,)), cam, gl_context)
    mesh = MeshInstance(asset(quad_part(0.01, 0.01, colour=RED)),
                        tuple(model_matrix(disc.centre_m, (0, 0, 0), 1.0).reshape(-1)))
    with Renderer(Scene((disc,), meshes=(mesh,)), RenderSettings(reuse_tolerance_px=None), ctx=gl_context) as r:
        r.render(cam)
        r.set_scene(Scene((disc,)))
        r.render(cam)
        assert np.array_equal(r.image(), fresh)


def test_a_blend_part_writes_no_depth_so_a_blend_part_behind_it_still_shows(gl_context):
    """BLEND parts are drawn with depth writes off (the framebuffer's depth mask: moderngl's Context has no
    depth_mask, so setting it there was a silent no-op): a BLEND glass drawn first in file order, in front of
    a second BLEND glass, must not depth-reject it."""
    from psyop.mesh.asset import AlphaMode

    def glass(colour, z_m):
        q = quad_part(0.01, 0.01, colour=colour, alpha_mode=AlphaMode.BLEND)
        return type(q)(**{**q.__dict__, "positions": q.positions + [0, 0, z_m],
                          "bbox_min": q.bbox_min + [0, 0, z_m], "bbox_max": q.bbox_max + [0, 0, z_m]})

    near, far = glass((0.0, 0.0, 1.0, 0.5), 0.1), glass((0.0, 1.0, 0.0, 0.5), 0.0)
    centre = RIGHT_CENTRE_M + np.array([0.0, 0.0, -1.0])
    inst = MeshInstance(asset(near, far), tuple(model_matrix(centre, (0, 0, 0), 1.0).reshape(-1)))
    cam = _window(right_eye_camera(0.0, 0.0, "conventional"), centre, 30)
    img = _render(Scene((), background=(0, 0, 0), meshes=(inst,)), cam, gl_context)
    x, y = project_points_px(cam, [centre])[0]
    # file order, premultiplied "over": blue (0, 0, 0.5) then green over it: (0, 0.5, 0.25); with depth
    # writes on, the far green glass would be rejected and the pixel would stay (0, 0, 0.5)
    assert img[int(y), int(x)] == pytest.approx([0.0, 0.5, 0.25], abs=1e-6)
