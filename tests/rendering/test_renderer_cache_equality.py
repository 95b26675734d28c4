"""The per-frame CPU savings of issue 21 change no number (timing: benchmarks/bench_frame_cpu.py):
the vectorised depth range and screen bounds equal the former per-primitive forms bit for bit, and a
renderer with its frame caches renders the same images and makes the same reuse decisions as the
former path (benchmarks/former.py's FormerRenderer)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.former import (FormerRenderer, depth_range_per_primitive_m, scene_in_head_per_primitive,
                               screen_bounds_px_former)
from psyop.optics import VIVE_PRO, make_eye_camera
from psyop.rendering import Renderer, RenderSettings, Scene, Solid
from psyop.rendering.camera_math import crop_camera
from psyop.rendering.renderer import create_headless_context
from psyop.rendering.scene import GridMaterial, NoiseTexture, Primitive, Shape, SineBorder
from psyop.rendering.screen_bounds import screen_bounds_px

pytestmark = pytest.mark.cross_cpu  # vectorised and cached against former paths, bit for bit

IPD_M, NC_M = 0.064, 0.0076916


def _random_scene(rng: np.random.Generator, n: int, with_infinity: bool) -> Scene:
    prims = []
    for i in range(n):
        u = rng.normal(size=3)
        v = np.cross(u, rng.normal(size=3))
        u, v = u / np.linalg.norm(u) * rng.uniform(0.01, 0.5), v / np.linalg.norm(v) * rng.uniform(0.01, 0.5)
        centre = rng.normal(size=3) * rng.uniform(0.1, 3.0)
        material = (Solid((0.2, 0.4, 0.6)), GridMaterial(), NoiseTexture(seed=i, size_px=8))[i % 3]
        prims.append(Primitive(Shape.DISC if i % 2 else Shape.RECT, tuple(centre), tuple(u), tuple(v), material,
                               name=f"p{i}", at_infinity=with_infinity and i == n - 1))
    return Scene(tuple(prims))


@pytest.mark.parametrize("with_infinity", [False, True])
def test_vectorised_depth_range_equals_the_per_primitive_one_bit_for_bit(with_infinity: bool) -> None:
    rng = np.random.default_rng(21)
    for n in (1, 2, 7, 64, 128):
        scene = _random_scene(rng, n, with_infinity)
        for _ in range(20):
            point = rng.normal(size=3) * rng.choice([0.01, 1.0, 5.0])
            assert scene.depth_range_m(point) == depth_range_per_primitive_m(scene, point)
    assert Scene(()).depth_range_m(np.zeros(3)) == depth_range_per_primitive_m(Scene(()), np.zeros(3))


def test_lean_screen_bounds_equal_the_former_ones_bit_for_bit() -> None:
    rng = np.random.default_rng(5)
    for trial in range(400):
        n = int(rng.integers(1, 40))
        cam = make_eye_camera(VIVE_PRO, "right", (rng.normal() * 0.3, rng.normal() * 0.3, -1.0), IPD_M, NC_M, "ocular")
        centres = rng.normal(size=(n, 3))
        centres[:, 2] -= rng.uniform(-0.5, 3.0, n)  # some behind the centre of projection: unbounded boxes
        if trial % 7 == 0:
            centres[0] = 0.0
        hu, hv = rng.normal(size=(n, 3)) * rng.uniform(0.01, 2.0), rng.normal(size=(n, 3)) * 0.3
        got = screen_bounds_px(centres, hu, hv, cam.pixel_to_ray, cam.width_px, cam.height_px)
        want = screen_bounds_px_former(centres, hu, hv, cam.pixel_to_ray, cam.width_px, cam.height_px)
        assert np.array_equal(got, want)


def _moving_scene(k: int) -> Scene:
    """A scene whose last primitive moves each frame (a circling target) over static ones."""
    a = 0.3 * k
    static = (Primitive(Shape.RECT, (0.0, 0.0, -2.0), (0.3, 0.0, 0.0), (0.0, 0.2, 0.0), NoiseTexture(seed=3, size_px=16),
                        name="wall"),
              Primitive(Shape.DISC, (0.05, 0.0, -1.0), (0.02, 0.0, 0.0), (0.0, 0.02, 0.0), Solid((1.0, 0.0, 0.0)),
                        border=SineBorder(0.3, 2.0), name="disc"),
              Primitive(Shape.RECT, (0.0, -0.3, -1.5), (0.5, 0.0, 0.0), (0.0, 0.0, 0.5), GridMaterial(), name="floor",
                        edge_samples_per_axis=4))
    target = Primitive(Shape.DISC, (0.2 * math.cos(a), 0.2 * math.sin(a), -1.0), (0.01, 0.0, 0.0), (0.0, 0.01, 0.0),
                       Solid((1.0, 1.0, 1.0)), name="target")
    return Scene(static + (target,))


def test_frame_caches_render_the_same_images_and_reuse_decisions() -> None:
    ctx = create_headless_context()
    renderers = {flag: (Renderer if flag else FormerRenderer)(_moving_scene(0), RenderSettings(), ctx=ctx)
                 for flag in (True, False)}
    try:
        statics = _moving_scene(0).primitives[:3]
        for k in range(24):
            moving = k < 12  # then a still scene and a still gaze: frames are reused
            scene = _moving_scene(k) if moving else _moving_scene(12)
            if k % 3:  # the same static primitive objects (as the session's cache hands them over)
                scene = Scene(statics + scene.primitives[3:])
            gaze = (0.02 * math.sin(0.2 * k), 0.01, -1.0) if moving or k % 4 == 0 else (0.02, 0.01, -1.0)
            for eye in ("left", "right"):
                cam = crop_camera(make_eye_camera(VIVE_PRO, eye, gaze, IPD_M, NC_M, "ocular"), 600, 700, 96, 80)
                for r in renderers.values():
                    r.set_scene(scene)
                results = {flag: r.render(cam) for flag, r in renderers.items()}
                assert results[True].rendered == results[False].rendered
                assert (results[True].reuse is None) == (results[False].reuse is None)
                if results[True].reuse is not None:
                    assert results[True].reuse == results[False].reuse
                assert np.array_equal(renderers[True].image(eye), renderers[False].image(eye)), (k, eye)
        fast, former = renderers[True].stats, renderers[False].stats
        assert (fast.frames_rendered, fast.frames_skipped) == (former.frames_rendered, former.frames_skipped)
        assert fast.frames_skipped > 0  # the still stretch was reused, so the lazy bounds were computed
    finally:
        for r in renderers.values():
            r.release()
        ctx.release()


def test_vectorised_scene_in_head_equals_the_per_primitive_one_bit_for_bit() -> None:
    from psyop.rendering.transform import scene_in_head

    rng = np.random.default_rng(8)
    for n in (1, 5, 64):
        scene = _random_scene(rng, n, with_infinity=True)
        for _ in range(10):
            q = rng.normal(size=4)
            t = rng.normal(size=3) * 0.1
            got, want = scene_in_head(scene, t, q), scene_in_head_per_primitive(scene, t, q)
            assert got == want and all(type(c) is float for p in got.primitives for c in p.centre_m)
    assert scene_in_head(scene, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)) is scene
    with pytest.raises(ValueError, match="finite"):
        scene_in_head(scene, (math.nan, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
