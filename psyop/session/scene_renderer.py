"""Frames with images: the protocol's stimulus (psyop.stimulus) ray-cast by psyop.rendering.

Used for every frame when a person watches, and for the sampled check frames of
headless simulated sessions (at reduced resolution: the check is that the image is
finite and not blank, which does not need full resolution).

Every image shown is checked (finite, not uniform unless blank by design) on the GPU, with
only a reduced summary read back (psyop.rendering.frame_check), never the whole float frame.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from collections.abc import Sequence
from typing import TYPE_CHECKING, Literal

import numpy as np

from psyop.session.choice_marker import with_marker
from psyop.session.rows import JsonObject, TrialRecord, TrialRow
from psyop.session.frames import FrameCheck, FrameRequest, HeadPose
from psyop.session.phases import PhaseSpec
from psyop.session.plan import SessionPlan

if TYPE_CHECKING:
    from psyop.mesh.load import MeshFiles


if TYPE_CHECKING:
    import moderngl

    from psyop.optics import EyeCamera
    from psyop.rendering import Renderer
    from psyop.rendering.frame_check import FrameChecker, FrameSummary
    from psyop.rendering.mesh_scene import MeshInstance
    from psyop.rendering.scene import Primitive, Scene

    #: a phase's time-independent parts (:meth:`SceneRenderer._static_parts`)
    StaticParts = tuple[Scene | None] | list[tuple[str, Scene | None]]


#: A real session (every frame rendered) checks each eye's first image of every phase and then
#: every 8th rendered one: the GPU reduction is cheap on a GPU but a full pass over the frame on llvmpipe
#: (benchmarks/bench_frame_path.py). Frames are logged with ``image_checked``.
WATCHED_CHECK_EVERY = 8


class SceneRenderer:
    """Implements the loop's FrameRenderer with real images, for the plan's eye(s).

    Intervals build the trial's scene at the time into the interval. When a person watches
    (``max_images`` None), the recalibration phase shows the central cross (its
    ``target_size_deg``), the response phase its text (the prompt, else the question: a head-fixed
    panel, psyop.stimulus.text_scene) and a blank phase its ``show:`` primitives (or the background);
    headless sampled checks (``max_images`` set) render interval frames only. A session screen
    (psyop.session.screens.ScreenPhase: instructions, a break, a questionnaire item, the end) is its text on
    the same head-fixed panel, its line breaks kept. Other phases
    compute cameras only. Cameras and eye centres come from the plan's eye rig.

    Per frame only what changes is built: eyes that share a scene origin (both eyes of a stereo
    protocol, :func:`psyop.stimulus.scene_origin_m`) share one scene, and the scene items that do not
    depend on time (:func:`psyop.stimulus.build.depends_on_time`: all but a moving fixation target) are
    built once per trial and phase, so a scene without a moving item is the same object every frame.
    The former path (the whole scene built for each eye, every frame) lives in benchmarks/former.py
    (``FormerSceneRenderer``), for the side-by-side benchmark (benchmarks/bench_frame_cpu.py) and the
    equality tests (tests/session/test_frame_cpu_equality.py: same scenes, same images).
    :meth:`_make_renderer` builds the ray-caster (psyop.rendering.Renderer) on the first drawn frame.
    """

    def __init__(self, plan: SessionPlan, *, scale: float = 1.0, ctx: moderngl.Context | None = None, max_images: int | None = None,
                 owns_ctx: bool = True, check_every: int | None = None,
                 mesh_files: MeshFiles | None = None) -> None:
        self.plan = plan
        self.protocol = plan.protocol
        display_profile = plan.display
        if scale != 1.0:
            display_profile = dataclasses.replace(display_profile, width_px=max(16, round(display_profile.width_px * scale)),
                                                  height_px=max(16, round(display_profile.height_px * scale)))
        self.display = display_profile
        self.rig = plan.rig
        self.eyes = plan.rig.eyes
        self._ctx = ctx
        self._owns_ctx = owns_ctx
        self.last_eye: str | None = None
        self._renderer: Renderer | None = None
        self._checker: FrameChecker | None = None
        self._summaries: dict[str, FrameSummary | None] = {}  # per eye: the check summary of its current image (None: unchecked)
        self._rendered: dict[str, int] = {}  # per eye: images rendered (not reused) in the current phase
        self._shown: JsonObject = {}  # per eye: (trial, phase) of the current image
        # 1: every rendered image is checked; n: each eye's first image of every phase and then
        # every n-th rendered one (a real session uses WATCHED_CHECK_EVERY; checked frames are logged)
        self.check_every = int(check_every) if check_every is not None else 1
        if self.check_every < 1:
            raise ValueError("check_every must be >= 1")
        self._base_dir = Path(plan.protocol.source_name).parent if plan.protocol.source_name else None
        from psyop.rendering.textures import ImageFiles

        self._images = ImageFiles(self._base_dir)  # image surfaces decoded once per session
        from psyop.stimulus.meshes import SessionMeshes

        self._meshes = SessionMeshes(self._base_dir, mesh_files)  # glTF models loaded once per session (uploaded once)
        from psyop.session.text_fit import session_texts

        # the session's text, laid out legibly on this display (refused here when it cannot fit), rasterised once
        self._texts = session_texts(plan, self.display, drawn=max_images is None)
        self.images_rendered = 0
        self.max_images = max_images  # None: every stimulus frame; n: only the first n (sampled checks)
        from psyop.rendering import AntiAliasing, RenderSettings

        # a check of finiteness and content needs no anti-aliasing; a watched session gets the default
        self.settings = RenderSettings(antialiasing=AntiAliasing.NONE) if max_images is not None else RenderSettings()
        # the time-independent parts of the current trial's scenes: per (phase, eye centre) either the whole
        # scene (nothing in it moves) or each shown item's primitives (None: the item moves, built per frame)
        self._parts_row: TrialRecord | None = None
        self._parts: dict[tuple[PhaseSpec, tuple[float, ...]], StaticParts] = {}

    def _scene(self, row: TrialRow, phase: PhaseSpec, t_in_phase_s: float, eye: str) -> Scene | None:
        """The scene this eye sees in this phase (head-fixed, or world-fixed before a head pose moves it),
        or None when nothing is drawn (cameras only)."""
        from psyop.stimulus import blank_scene, build_scene, recalibration_cross_scene, scene_origin_m, text_scene

        centre = self.rig.centre_m(eye)
        watched = self.max_images is None
        if phase.show == "cross":
            return recalibration_cross_scene(centre, arm_deg=phase.target_size_deg) if watched else None
        if phase.show == "target":  # a gaze validation target, head-fixed (psyop.session.validation)
            from psyop.session.validation import TargetPhase, validation_target_scene

            return validation_target_scene(phase) if watched and isinstance(phase, TargetPhase) else None
        if phase.show == "text":  # a session screen (psyop.session.screens): its text, head-fixed, lines kept
            from psyop.session.screens import ScreenPhase

            if not (watched and isinstance(phase, ScreenPhase) and phase.text.strip()):
                return None
            if phase.image is not None:  # an instruction page's picture above its text
                from psyop.rendering.text import Picture

                page = self._texts.page(phase.text, Picture(str((self._base_dir or Path(".")) / phase.image),
                                                           phase.image_width_deg))
                return text_scene(page, scene_origin_m(self.protocol, centre))
            origin = scene_origin_m(self.protocol, centre)
            return with_marker(text_scene(self._texts.image(phase.text, keep_lines=True), origin), phase.marker_deg,
                               tuple(origin))
        text = self.plan.response.participant_text
        if phase == self.plan.response.phase and text is not None:  # head-fixed, like the cross
            image = self._texts.image(text, keep_lines=self.plan.response.keeps_lines) if watched else None
            return None if image is None else text_scene(image, scene_origin_m(self.protocol, centre))
        if phase.show == "blank" and not phase.primitives:
            return blank_scene() if watched else None
        if phase.show == "blank" and not watched:
            return None
        if phase.show not in ("stimulus", "blank"):
            return None
        return build_scene(self.protocol, row, t_in_phase_s, centre, interval=max(1, phase.interval),
                           base_dir=self._base_dir, show=phase.primitives, images=self._images, meshes=self._meshes)

    def _frame_scene(self, row: TrialRow, phase: PhaseSpec, t_in_phase_s: float, eye: str,
                     head_pose: HeadPose | None, frame_scenes: dict[tuple[float, ...], Scene | None]) -> Scene | None:
        """:meth:`_scene` for this frame, each scene built once for the eyes that share it and only its moving
        items rebuilt (see the class docstring); ``frame_scenes``: this frame's scenes so far, by eye centre or
        scene origin."""
        from psyop.rendering.transform import scene_in_head
        from psyop.stimulus import scene_origin_m

        centre = self.rig.centre_m(eye)
        # the cross is built around the eye's own centre; every other scene around the scene origin
        where = centre if phase.show == "cross" else (0.0, 0.0, 0.0) if phase.show == "target" else \
            scene_origin_m(self.protocol, centre)
        key = tuple(float(c) for c in where)
        if key not in frame_scenes:
            scene = self._world_scene(row, phase, t_in_phase_s, eye)
            if scene is not None and head_pose is not None and not self._head_fixed(phase):  # world-fixed
                scene = scene_in_head(scene, *head_pose)
            frame_scenes[key] = scene
        return frame_scenes[key]

    def _head_fixed(self, phase: PhaseSpec) -> bool:
        """Whether :meth:`_scene` draws this phase head-fixed (the cross, the response text, an empty blank),
        not as the world-fixed stimulus a tracked head moves through."""
        text = phase == self.plan.response.phase and self.plan.response.participant_text is not None
        return phase.show in ("cross", "target", "text") or text or (phase.show == "blank" and not phase.primitives)

    def _world_scene(self, row: TrialRow, phase: PhaseSpec, t_in_phase_s: float, eye: str) -> Scene | None:
        """:meth:`_scene` without a head pose, from the trial's cached time-independent parts."""
        from psyop.rendering.scene import Scene
        from psyop.stimulus import build_scene

        if self._parts_row is None or row != self._parts_row:  # a new trial (or row): nothing cached applies
            self._parts_row, self._parts = dict(row), {}
        centre = self.rig.centre_m(eye)
        key = (phase, tuple(float(c) for c in centre))
        parts = self._parts.get(key)
        if parts is None:
            parts = self._parts[key] = self._static_parts(row, phase, eye)
        if isinstance(parts, tuple):
            return parts[0]
        prims: list[Primitive] = []
        meshes: list[MeshInstance] = []
        aperture = None
        output = None  # a calibrated display's final pass (psyop.rendering.scene.OutputTransfer), the same in every part
        background = Scene(()).background
        for item_id, part in parts:
            if part is None:  # a moving item: built for this frame's time
                part = build_scene(self.protocol, row, t_in_phase_s, centre, interval=max(1, phase.interval),
                                   base_dir=self._base_dir, show=(item_id,), images=self._images, meshes=self._meshes)
            prims += part.primitives
            meshes += part.meshes
            aperture = part.aperture if part.aperture is not None else aperture
            output, background = part.output, part.background
        return Scene(tuple(prims), background=background, aperture=aperture, meshes=tuple(meshes), output=output)

    def _static_parts(self, row: TrialRow, phase: PhaseSpec, eye: str) -> StaticParts:
        """What of this phase's scene does not depend on time: ``(scene,)`` when nothing in it moves (the
        whole scene, or None), else ``[(id, its one-item scene, or None for an item that moves)]`` for
        every shown item in the protocol's order (the order is the layer order; the last aperture wins)."""
        from psyop.stimulus import build_scene, interval_phases
        from psyop.stimulus.build import depends_on_time

        whole = self._scene(row, phase, 0.0, eye)
        if whole is None or phase.show not in ("stimulus", "blank") or self._head_fixed(phase):
            return (whole,)  # the cross, the text, an empty blank, nothing drawn: never move
        interval = max(1, phase.interval)
        show: Literal["all"] | Sequence[str] | None = phase.primitives
        if show is None:  # build_scene's default: the interval's own show: list
            phases = interval_phases(self.protocol)
            show = phases[interval - 1].show if 0 < interval <= len(phases) else "all"
        shown = [item for item in self.protocol.scene if show == "all" or item.id in show]
        if not any(depends_on_time(item) for item in shown):
            return (whole,)
        centre = self.rig.centre_m(eye)
        return [(item.id, None if depends_on_time(item) else
                 build_scene(self.protocol, row, 0.0, centre, interval=interval, base_dir=self._base_dir,
                             show=(item.id,), images=self._images, meshes=self._meshes))
                for item in shown]

    def _make_renderer(self, scene: Scene) -> Renderer:
        """The session's ray-caster, built on its first drawn frame (benchmarks/former.py builds the former one)."""
        from psyop.rendering import Renderer

        return Renderer(scene, settings=self.settings, ctx=self._ctx)

    def _camera(self, eye: str, fixation_m: tuple[float, float, float], mode: str, frame: FrameRequest | None,
                row: TrialRow | None = None) -> EyeCamera:
        """This eye's camera: from the display's view and at its target's size where the display
        gives them (a headset runtime), else from the protocol's display profile and the rig; ``row``
        (the trial) sets a rendered NC that is a factor (display.rendering_nc)."""
        view = frame.view(eye) if frame is not None else None
        target = frame.targets.get(eye) if frame is not None else None
        if view is None:
            if target is not None and (target.width_px, target.height_px) != (self.display.width_px, self.display.height_px):
                display = dataclasses.replace(self.display, width_px=target.width_px, height_px=target.height_px)
                return self.rig.camera(display, eye, fixation_m, mode, row=row)
            return self.rig.camera(self.display, eye, fixation_m, mode, row=row)
        width, height = (target.width_px, target.height_px) if target is not None else (self.display.width_px,
                                                                                         self.display.height_px)
        return self.rig.view_camera(view, width, height, fixation_m, mode, row=row)

    def render(self, row: TrialRow, phase: PhaseSpec, mode: str, t_in_phase_s: float,
               fixation_m: tuple[float, float, float], head_pose: HeadPose | None = None,
               frame: FrameRequest | None = None) -> FrameCheck:
        """Render this frame for the plan's eye(s) in ``mode`` (the plan's mode of this phase).
        ``head_pose`` (tracked, head -> world) moves the eyes through the world-fixed stimulus;
        the recalibration cross stays head-fixed. ``frame``: the display's request; each eye is
        drawn from its view and copied into its target where the request has them."""
        cameras_ok = True
        ok = True
        images = checked = 0
        if self.max_images is None and frame is not None and frame.targets:  # a headset's images: text fits them
            from psyop.session.text_fit import refit_texts

            texts = refit_texts(self._texts, self.plan, self.display, frame)
            if texts is not self._texts:  # laid out anew: no scene built with the former layout is reused
                self._texts, self._parts_row = texts, None
        frame_scenes: dict[tuple[float, ...], Scene | None] = {}
        for eye in self.eyes:
            camera = self._camera(eye, fixation_m, mode, frame, row)
            cameras_ok &= bool(np.isfinite(camera.view).all() and np.isfinite(camera.projection).all())
            if phase.show == "stimulus" and self.max_images is not None and self.images_rendered >= self.max_images:
                return FrameCheck(False, cameras_ok)
            scene = self._frame_scene(row, phase, t_in_phase_s, eye, head_pose, frame_scenes)
            target = frame.targets.get(eye) if frame is not None else None
            if scene is None:
                if target is not None:  # nothing drawn: the eye sees the background, not a stale image
                    target.framebuffer.clear(*self._background(), 1.0)
                continue
            if self._renderer is None:
                self._renderer = self._make_renderer(scene)
            else:
                self._renderer.set_scene(scene)
            result = self._renderer.render(camera)
            if target is not None:  # the display's image (a swapchain image) gets this eye's frame
                self._renderer.copy_to(eye, target.framebuffer)
            self.images_rendered += 1
            self.last_eye = eye
            images += 1
            shown = (row.get("trial"), phase.name)
            if self._shown.get(eye) != shown:  # a new phase: its first image is checked
                self._shown[eye], self._rendered[eye] = shown, 0
                result_is_new = True
            else:
                result_is_new = result.rendered
            if result_is_new or eye not in self._summaries:  # a reused frame keeps its check (or none)
                n = self._rendered[eye] = self._rendered.get(eye, 0) + 1
                self._summaries[eye] = self._check(eye) if (n - 1) % self.check_every == 0 else None
            summary = self._summaries[eye]
            if summary is not None:
                checked += 1
                # a blank may be uniform by design (nothing shown, or only e.g. an aperture's surround)
                ok &= summary.ok(blank_by_design=phase.show == "blank")
        return FrameCheck(checked > 0, ok and cameras_ok)

    def _background(self) -> tuple[float, float, float]:
        from psyop.stimulus import blank_scene

        r, g, b = blank_scene().background if self._renderer is None else self._renderer.scene.background
        return (r, g, b)

    def _check(self, eye: str) -> FrameSummary:
        """The frame's check summary, reduced on the GPU (no full readback)."""
        renderer = self._renderer
        assert renderer is not None, "checked after this eye's image was rendered"
        if self._checker is None:
            from psyop.rendering.frame_check import FrameChecker

            self._checker = FrameChecker(renderer.ctx)
        return self._checker.summarise(renderer.colour_texture(eye))

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

    def linear_image(self, eye: str) -> np.ndarray | None:
        """(H, W, 3) float32, top row first: ``eye``'s latest image before the display's final pass
        (psyop.rendering.Renderer.linear_image); None before anything is drawn."""
        return None if self._renderer is None else self._renderer.linear_image(eye)

    def eye_textures(self) -> list[moderngl.Texture]:
        """Each eye's latest image as a colour texture, left eye first; [] until every eye has one."""
        if self._renderer is None:
            return []
        try:
            return [self._renderer.colour_texture(eye) for eye in self.eyes]
        except KeyError:
            return []

