"""Numerical stability: degenerate fixations, extreme clip planes, float32 evaluation."""

from __future__ import annotations

import math

import numpy as np

from psyop.optics.camera import clip_to_pixels, eye_camera_arrays, make_eye_camera, project_to_pixels
from psyop.optics.display import VIVE_PRO, DisplayProfile

CASES = 100_000


def _random_fixations(rng, n, centre):
    """Mixed normal and degenerate fixations (homogeneous 4-vectors) and the validity expected."""
    kind = rng.integers(0, 8, n)
    ecc = np.radians(rng.uniform(0.0, 89.0, n))
    az = rng.uniform(0.0, 2 * np.pi, n)
    unit = np.stack([np.sin(ecc) * np.cos(az), np.sin(ecc) * np.sin(az), -np.cos(ecc)], axis=1)
    dist = 10 ** rng.uniform(-2, 4, n)  # 1 cm .. 10 km: valid
    fix = np.concatenate([centre + dist[:, None] * unit, np.ones((n, 1))], axis=1)
    expect_valid = np.ones(n, dtype=bool)
    # 1: at infinity (valid direction)
    m = kind == 1
    fix[m, :3], fix[m, 3] = unit[m], 0.0
    # 2: exactly at the eye centre
    m = kind == 2
    fix[m, :3], expect_valid[m] = centre, False
    # 3: very near the eye centre (1e-12 .. 1e-3 m)
    m = kind == 3
    fix[m, :3] = centre + (10 ** rng.uniform(-12, -3, m.sum()))[:, None] * unit[m]
    expect_valid[m] = False
    # 4: behind or beside the eye (91-180 deg from straight ahead)
    m = kind == 4
    back = np.radians(rng.uniform(91.0, 180.0, m.sum()))
    fix[m, :3] = centre + np.stack([np.sin(back), np.zeros_like(back), -np.cos(back)], axis=1)
    expect_valid[m] = False
    # 5: NaN anywhere
    m = kind == 5
    fix[m, rng.integers(0, 4, m.sum())] = np.nan
    expect_valid[m] = False
    # 6: infinite components, or a zero direction at infinity
    m = kind == 6
    fix[m, 2] = -np.inf
    expect_valid[m] = False
    m = kind == 7
    fix[m] = 0.0
    expect_valid[m] = False
    return fix, expect_valid


def test_hundred_thousand_degenerate_and_extreme_cases_stay_finite_and_flagged():
    rng = np.random.default_rng(20201)
    chunks = 20
    n = CASES // chunks
    total_invalid = 0
    for i in range(chunks):
        d_m = math.inf if i % 2 == 0 else float(10 ** rng.uniform(-1, 3))
        display = DisplayProfile("x", 1440, 1600, 90.0, -1.4, 1.3, -1.5, 1.45, d_m)
        eye = "left" if i % 3 else "right"
        mode = ("conventional", "ocular", "reversed")[i % 3]
        ipd, nc = rng.uniform(0.05, 0.078), rng.uniform(0.004, 0.01)
        centre = np.array([(-0.5 if eye == "left" else 0.5) * ipd, 0.0, 0.0])
        fix, expect_valid = _random_fixations(rng, n, centre)
        near = 10 ** rng.uniform(-4, 3, n)
        far = np.minimum(near * 10 ** rng.uniform(0.01, 8, n), 1e4)
        near = np.minimum(near, far / 1.001)
        fallback = np.array([0.1, 0.0, -1.0])
        cams = eye_camera_arrays(display, eye, fix, ipd, nc, mode, near, far, fallback_direction=fallback)
        for arr in (cams.view, cams.projection, cams.pixel_to_ray, cams.tangents, cams.centre_of_projection_m):
            assert np.isfinite(arr).all()
        np.testing.assert_array_equal(cams.valid, expect_valid)
        # the fallback is the given direction, so a flagged frame sits exactly there
        fb_unit = fallback / np.linalg.norm(fallback)
        if mode != "conventional":
            sign = np.array([1.0, 1.0, 1.0]) if mode == "ocular" else np.array([-1.0, -1.0, 1.0])
            np.testing.assert_allclose(cams.centre_of_projection_m[~cams.valid],
                                       np.broadcast_to(centre + nc * sign * fb_unit, (int((~cams.valid).sum()), 3)), atol=1e-15)
        # every frustum is non-degenerate: R > L, T > B, and the depth row is finite and ordered
        assert (cams.tangents[:, 1] > cams.tangents[:, 0]).all() and (cams.tangents[:, 3] > cams.tangents[:, 2]).all()
        assert (np.abs(np.linalg.det(cams.projection)) > 0).all()
        total_invalid += int((~cams.valid).sum())
    assert total_invalid > CASES // 2  # the degenerate classes were really exercised


def test_bad_fallback_direction_falls_back_to_straight_ahead():
    cam = make_eye_camera(VIVE_PRO, "right", [np.nan, 0, 0], 0.064, 0.0076916, "ocular",
                          fallback_direction=[0.0, 0.0, 1.0])  # behind: unusable too
    assert not cam.valid
    np.testing.assert_allclose(cam.centre_of_projection_m, [0.032, 0.0, -0.0076916], atol=1e-15)


def _float32_errors(world_offset_m, rng, n=20_000):
    """Max pixel error vs float64 of (a) camera-relative float32 and (b) naive absolute float32."""
    worst_rel, worst_naive = 0.0, 0.0
    for ecc in (0.0, 15.0, 30.0):
        gaze = [math.sin(math.radians(ecc)), 0.0, -math.cos(math.radians(ecc))]
        cam = make_eye_camera(VIVE_PRO, "right", np.append(gaze, 0.0), 0.064, 0.0076916, "ocular", 0.01, 1000.0)
        z = 10 ** rng.uniform(-1, 3, n)  # 0.1 m .. 1 km
        pts = np.stack([rng.uniform(-1.4, 1.4, n) * z, rng.uniform(-1.5, 1.5, n) * z, -z], axis=1)
        ref = project_to_pixels(cam, pts)
        offset = np.asarray(world_offset_m, dtype=np.float64)
        # (a) camera-relative: eye-space positions formed in float64 (as when the scene's model
        # matrix is composed with the view in float64), then projection in float32
        rel = (pts - cam.centre_of_projection_m).astype(np.float32)
        clip_a = np.concatenate([rel, np.ones((n, 1), np.float32)], axis=1) @ cam.projection.astype(np.float32).T
        # (b) naive: world-space float32 vertices and a float32 model-view-projection whose
        # translation holds the absolute camera position
        world = (pts + offset).astype(np.float32)
        view_world = cam.view.copy()
        view_world[:3, 3] -= offset
        mvp = (cam.projection @ view_world).astype(np.float32)
        clip_b = np.concatenate([world, np.ones((n, 1), np.float32)], axis=1) @ mvp.T
        for clip, name in ((clip_a, "rel"), (clip_b, "naive")):
            px = clip_to_pixels(clip.astype(np.float64), cam.width_px, cam.height_px)
            err = float(np.nanmax(np.abs(px - ref)))
            if name == "rel":
                worst_rel = max(worst_rel, err)
            else:
                worst_naive = max(worst_naive, err)
    return worst_rel, worst_naive


def test_camera_relative_float32_within_a_hundredth_of_a_pixel():
    rng = np.random.default_rng(7)
    rel, naive_head = _float32_errors([0.0, 0.0, 0.0], rng)
    assert rel < 0.01
    _, naive_room = _float32_errors([3.0, 1.6, -2.0], rng)
    _, naive_far = _float32_errors([1000.0, 1.6, -500.0], rng)
    print(f"float32 max px error: camera-relative {rel:.2e}, naive head-origin {naive_head:.2e}, "
          f"naive room offset {naive_room:.2e}, naive 1 km offset {naive_far:.2e}")
    # absolute coordinates lose the millimetre shift once they are large
    assert naive_far > 0.01 > rel
    assert naive_far > 10 * rel


def test_single_frame_path_agrees_with_vectorised_path_on_degenerate_cases():
    """make_eye_camera (scalar per-frame path) == eye_camera_arrays (batch) case by case."""
    rng = np.random.default_rng(5)
    for d_m, eye, mode in ((math.inf, "left", "ocular"), (0.7, "right", "reversed"), (2.0, "left", "conventional")):
        display = DisplayProfile("x", 1440, 1600, 90.0, -1.4, 1.3, -1.5, 1.45, d_m)
        centre = np.array([(-0.032 if eye == "left" else 0.032), 0.0, 0.0])
        fix, expect_valid = _random_fixations(rng, 400, centre)
        fallback = [0.2, 0.1, -1.0]
        batch = eye_camera_arrays(display, eye, fix, 0.064, 0.0076916, mode, 0.05, 500.0, fallback_direction=fallback)
        for i in range(len(fix)):
            cam = make_eye_camera(display, eye, fix[i], 0.064, 0.0076916, mode, 0.05, 500.0, fallback_direction=fallback)
            assert cam.valid == bool(batch.valid[i]) == bool(expect_valid[i])
            np.testing.assert_allclose(cam.projection, batch.projection[i], rtol=1e-13, atol=1e-15)
            np.testing.assert_allclose(cam.view, batch.view[i], rtol=0, atol=1e-16)
            np.testing.assert_allclose(cam.pixel_to_ray, batch.pixel_to_ray[i], rtol=1e-13, atol=1e-15)
