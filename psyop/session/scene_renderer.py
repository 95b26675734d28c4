"""Frames with images: the protocol's stimulus (psyop.stimulus) ray-cast by psyop.rendering.

Used for every frame when a person watches, and for the sampled check frames of
headless simulated sessions (at reduced resolution: the check is that the image is
finite and not blank, which does not need full resolution).

Every image shown is checked (finite, not uniform unless blank by design) on the GPU, with
only a reduced summary read back (psyop.rendering.frame_check), never the whole float frame.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from psyop.session.frames import FrameCheck, HeadPose
from psyop.session.phases import PhaseSpec


class SceneRenderer:
    """Implements the loop's FrameRenderer with real images for interval phases.

    Intervals build the trial's scene at the time into the interval and render it for the
    protocol's eye(s). When a person watches (``max_images`` None), the recalibration phase
    shows the central cross and the blank phase the background; headless sampled checks
    (``max_images`` set) render stimulus frames only. Other phases compute cameras only.
    """

    def __init__(self, protocol: Any, display_profile: Any, ipd_m: float, nc_m: float, *, scale: float = 1.0,
                 ctx: Any = None, max_images: int | None = None, owns_ctx: bool = True) -> None:
        from psyop.optics import make_eye_camera

        self.protocol = protocol
        if scale != 1.0:
            display_profile = dataclasses.replace(display_profile, width_px=max(16, round(display_profile.width_px * scale)),
                                                  height_px=max(16, round(display_profile.height_px * scale)))
        self.display = display_profile
        self.ipd_m, self.nc_m = ipd_m, nc_m
        eyes = getattr(protocol, "eyes", "right")
        self.eyes = ("left", "right") if eyes == "stereo" else (str(eyes),)
        self._make_camera = make_eye_camera
        self._ctx = ctx
        self._owns_ctx = owns_ctx
        self.last_eye: str | None = None
        self._renderer: Any = None
        self._checker: Any = None
        self._base_dir = Path(protocol.source_name).parent if getattr(protocol, "source_name", "") else None
        from psyop.rendering.textures import ImageFiles

        self._images = ImageFiles(self._base_dir)  # image surfaces decoded once per session
        self.images_rendered = 0
        self.max_images = max_images  # None: every stimulus frame; n: only the first n (sampled checks)
        from psyop.rendering import AntiAliasing, RenderSettings

        # a check of finiteness and content needs no anti-aliasing; a watched session gets the default
        self.settings = RenderSettings(antialiasing=AntiAliasing.NONE) if max_images is not None else RenderSettings()

    def _centre(self, eye: str) -> np.ndarray:
        return np.array([(-0.5 if eye == "left" else 0.5) * self.ipd_m, 0.0, 0.0])

    def render(self, row: Mapping[str, Any], phase: PhaseSpec, mode: str, t_in_phase_s: float,
               fixation_m: tuple[float, float, float], head_pose: HeadPose | None = None) -> FrameCheck:
        """Render this frame for the protocol's eye(s). ``head_pose`` (tracked, head -> world)
        moves the eyes through the world-fixed stimulus; the recalibration cross stays head-fixed."""
        from psyop.rendering import Renderer
        from psyop.rendering.transform import scene_in_head
        from psyop.stimulus import blank_scene, build_scene, interval_mode, recalibration_cross_scene

        cameras_ok = True
        interval = int(phase.name.removeprefix("interval")) if phase.name.startswith("interval") else 0
        if interval:
            try:
                mode = interval_mode(self.protocol, row, interval)
            except Exception:  # noqa: BLE001 - fall back to the loop's mode mapping
                pass
        ok = True
        images = 0
        for eye in self.eyes:
            camera = self._make_camera(self.display, eye, fixation_m, self.ipd_m, self.nc_m,
                                       mode if phase.show == "stimulus" else "conventional")
            cameras_ok &= bool(np.isfinite(camera.view).all() and np.isfinite(camera.projection).all())
            if phase.show in ("cross", "blank") and self.max_images is None:
                scene = (recalibration_cross_scene(self._centre(eye)) if phase.show == "cross" else blank_scene())
            elif interval and phase.show == "stimulus":
                if self.max_images is not None and self.images_rendered >= self.max_images:
                    return FrameCheck(False, cameras_ok)
                scene = build_scene(self.protocol, row, t_in_phase_s, self._centre(eye), interval=interval,
                                    base_dir=self._base_dir, images=self._images)
                if head_pose is not None:
                    scene = scene_in_head(scene, *head_pose)
            else:
                continue
            if self._renderer is None:
                self._renderer = Renderer(scene, settings=self.settings, ctx=self._ctx)
            else:
                self._renderer.set_scene(scene)
            self._renderer.render(camera)
            self.images_rendered += 1
            self.last_eye = eye
            images += 1
            ok &= self._check(eye).ok(blank_by_design=phase.show == "blank")  # a blank frame is uniform by design
        return FrameCheck(images > 0, ok and cameras_ok)

    def _check(self, eye: str) -> Any:
        """The frame's check summary, reduced on the GPU (no full readback)."""
        if self._checker is None:
            from psyop.rendering.frame_check import FrameChecker

            self._checker = FrameChecker(self._renderer.ctx)
        return self._checker.summarise(self._renderer.colour_texture(eye))

    def close(self) -> None:
        if self._checker is not None:
            self._checker.release()
            self._checker = None
        if self._renderer is not None:
            self._renderer.release()
            self._renderer = None
        if self._ctx is not None and self._owns_ctx:
            self._ctx.release()
        self._ctx = None

    def last_framebuffer(self) -> Any:
        """The framebuffer of the last rendered eye (for a window to present), or None."""
        if self._renderer is None or self.last_eye is None:
            return None
        return self._renderer.framebuffer(self.last_eye)
