"""Accuracy measurements of rendered images against exact ray geometry (shared by the tests'
numbers, the benchmarks and docs/rendering.md).

``detection_area_errors``: visible red area of the detection stimulus in ocular mode (and the
red leaked in conventional mode) versus the exact circle-overlap prediction.
``border_position_errors``: per-row mean border position of the ordinal stimulus versus the
exact projected sinusoid, in pixels.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import moderngl
import numpy as np

from psyop.optics.camera import EyeCamera, make_eye_camera
from psyop.optics.display import VIVE_PRO, DisplayProfile
from psyop.optics.nodal import eye_centre_m
from psyop.rendering.builders import detection_stimulus, direction_from_angles, ordinal_stimulus
from psyop.rendering.camera_math import crop_camera, project_points_px
from psyop.rendering.exact import border_x_px, visible_back_area_px
from psyop.rendering.renderer import Renderer, RenderSettings
from psyop.rendering.scene import Scene, Solid

#: the measurement's fixed geometry (not a session's ipd, which is psyop.optics.ranges'): 64 mm apart
FIXTURE_IPD_M = 0.064
NC_M = 0.0076916  # Gullstrand-Emsley relaxed eye, DESIGN.md
RIGHT_CENTRE_M = eye_centre_m("right", FIXTURE_IPD_M)
GAZE_DEG = (16.0 * math.cos(0.7), 16.0 * math.sin(0.7))


def right_eye_camera(az_deg: float, el_deg: float, mode: str, display: DisplayProfile = VIVE_PRO,
                     eye: str = "right", near_m: float = 0.01, far_m: float = 100.0) -> EyeCamera:
    """Camera of ``eye`` fixating 0.5 m away in direction (az, el) from the *right* eye's centre
    (64 mm IPD, Gullstrand-Emsley NC)."""
    fixation = RIGHT_CENTRE_M + direction_from_angles(az_deg, el_deg) * 0.5
    return make_eye_camera(display, eye, fixation, FIXTURE_IPD_M, NC_M, mode, near_m, far_m)


@dataclass(frozen=True)
class AreaErrors:
    worst_relative: float  # max |measured - exact| / exact over the configurations
    conventional_leak_px2: float  # largest red area measured in conventional mode


def _red_area(img: np.ndarray) -> float:
    return float(np.sum(img[..., 0].astype(np.float64) - img[..., 1]))


def detection_area_errors(settings: RenderSettings, ctx: moderngl.Context | None, backs_D: tuple[float, ...] = (1.0, 2.0, 3.0),
                          rels_D: tuple[float, ...] = (0.25, 0.5, 1.0), half_px: int = 24) -> AreaErrors:
    worst, leak = 0.0, 0.0
    for back_D in backs_D:
        for rel_D in rels_D:
            back, front = detection_stimulus(back_D, rel_D, origin_m=RIGHT_CENTRE_M)
            with Renderer(Scene((back, front)), settings, ctx=ctx) as renderer:
                for mode in ("ocular", "conventional"):
                    full = right_eye_camera(*GAZE_DEG, mode)
                    c = project_points_px(full, [back.centre_m])[0]
                    cam = crop_camera(full, int(c[0]) - half_px, int(c[1]) - half_px, 2 * half_px, 2 * half_px)
                    renderer.render(cam)
                    measured = _red_area(renderer.image())
                    if mode == "ocular":
                        exact = visible_back_area_px(cam, back, front)
                        worst = max(worst, abs(measured - exact) / exact)
                    else:
                        leak = max(leak, abs(measured))
    return AreaErrors(worst, leak)


def border_position_errors(settings: RenderSettings, ctx: moderngl.Context | None, mode: str = "ocular") -> np.ndarray:
    """|measured - exact| mean border x per image row (px) for the ordinal stimulus."""
    rear, front = ordinal_stimulus(0.5, 2.5, "left", origin_m=RIGHT_CENTRE_M, amplitude_deg=1.0, cycles=3.0,
                                   phase_rad=0.4)
    rear = dataclasses.replace(rear, material=Solid((0.0, 0.0, 0.0)))
    front = dataclasses.replace(front, material=Solid((1.0, 1.0, 1.0)))
    full = right_eye_camera(9.0, -5.0, mode)
    centre = project_points_px(full, [front.centre_m])[0]
    w, h = 48, 80
    cam = crop_camera(full, int(centre[0]) - w // 2, int(centre[1]) - h // 2, w, h)
    with Renderer(Scene((rear, front)), settings, ctx=ctx) as renderer:
        renderer.render(cam)
        img = renderer.image()
    measured = img[..., 1].astype(np.float64).sum(axis=1)
    rows = np.arange(h)[:, None] + (np.arange(64) + 0.5)[None, :] / 64.0
    exact = border_x_px(cam, front, rows.ravel()).reshape(h, 64).mean(axis=1)
    return np.abs(measured - exact)


def straight_edge_errors(ctx: moderngl.Context | None, samples: tuple[int, ...] = (1, 2, 4, 8, 16, 32)) -> dict[int, tuple[float, float]]:
    """Max and mean |rendered - exact| / contrast over the edge pixels of a slanted, receding
    solid rect (a room-like straight edge), per samples per axis (1 = one ray per pixel)."""
    from psyop.rendering.exact_coverage import coverage_px, projected_corners_px
    from psyop.rendering.scene import Primitive, Shape
    from psyop.rendering.shaders import AntiAliasing

    cam = crop_camera(right_eye_camera(0.0, 0.0, "ocular"), 720 - 64, 840, 128, 128)
    a = np.radians(20.0)
    rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    floor = Primitive(Shape.RECT, (0.05, -0.3, -1.6), tuple(rot @ [0.3, 0, 0]), tuple(rot @ [0, 0, 0.6]),
                      Solid((0.9, 0.9, 0.9)), name="floor")
    cov = coverage_px(projected_corners_px(cam, floor), cam.width_px, cam.height_px)
    expected, edge = 0.5 + 0.4 * cov, (cov > 0) & (cov < 1)
    out = {}
    for n in samples:
        settings = RenderSettings(antialiasing=AntiAliasing.NONE) if n == 1 else RenderSettings()
        prim = floor if n == 1 else dataclasses.replace(floor, edge_samples_per_axis=n)
        with Renderer(Scene((prim,), background=(0.5, 0.5, 0.5)), settings, ctx=ctx) as r:
            r.render(cam)
            err = np.abs(r.image("right")[..., 0].astype(np.float64) - expected)[edge] / 0.4
        out[n] = (float(err.max()), float(err.mean()))
    return out
