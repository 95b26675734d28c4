"""The former per-frame paths (before issue 21's frame caches), kept outside production for the
side-by-side benchmark (benchmarks/bench_frame_cpu.py, the "before" column) and the equality tests
that hold the cached paths to them (tests/rendering/test_renderer_cache_equality.py,
tests/session/test_frame_cpu_equality.py: same images, same reuse decisions, same scenes).

- :class:`FormerRenderer`: psyop.rendering.Renderer with every per-frame cache off: constant
  uniforms (block bindings, sampler units) written every frame, every scene uniform written each
  time it is set, the primitive table packed again on every scene change, a program's names walked
  on every lookup, the reuse bounds computed one primitive at a time after every draw, the screen
  bounds in their first form.
- the reference forms the vectorised per-frame maths is held to bit for bit:
  :func:`depth_range_per_primitive_m` (``Scene.depth_range_m``), :func:`screen_bounds_px_former`
  (``psyop.rendering.screen_bounds.screen_bounds_px``), :func:`scene_in_head_per_primitive`
  (``psyop.rendering.transform.scene_in_head``).
- :class:`FormerSceneRenderer`: psyop.session.scene_renderer.SceneRenderer building the whole scene
  for each eye, every frame, moved into head space one primitive at a time, drawn by a
  :class:`FormerRenderer`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from psyop.rendering.renderer import Renderer, _EyeState
from psyop.rendering.scene import Scene
from psyop.rendering.screen_bounds import UNBOUNDED_PX
from psyop.rendering.transform import IDENTITY_WXYZ, _moved_meshes, rotate_rows, rotation_matrix
from psyop.session.scene_renderer import SceneRenderer

if TYPE_CHECKING:
    import moderngl

    from psyop.optics.camera import EyeCamera
    from psyop.session.frames import HeadPose
    from psyop.session.phases import PhaseSpec
    from psyop.session.rows import TrialRow


class FormerRenderer(Renderer):
    """:class:`psyop.rendering.Renderer` without its frame caches (same images, same reuse decisions)."""

    def _set_constant_uniforms(self) -> None:
        """Not once at set-up: :meth:`_draw` writes them every frame."""

    def _draw(self, state: _EyeState, camera: EyeCamera | None) -> None:
        if camera is not None:  # the former draw wrote the bindings and sampler units with each frame's uniforms
            Renderer._set_constant_uniforms(self)
        super()._draw(state, camera)

    def _upload_primitives(self, scene: Scene, layer_of: dict) -> None:
        super()._upload_primitives(scene, layer_of)
        self._packed = {}  # nothing kept: every row is packed again with the next scene

    def _set_if_present(self, name: str, value: object) -> None:
        for prog in self._programs():  # written every time, changed or not
            if name in self._members(prog):
                prog[name].value = value  # type: ignore[union-attr]  # a uniform (the shader declares it)

    def _members(self, prog: moderngl.Program) -> moderngl.Program:
        return prog  # ``name in prog`` walks the program's members on every lookup

    def _keep_depth_centre(self, state: _EyeState, cop: np.ndarray) -> None:
        state.depth_range_m = depth_range_per_primitive_m(self.scene, cop)  # after every draw

    def _screen_bounds_px(self, rel_m: np.ndarray, camera: EyeCamera, state: _EyeState) -> np.ndarray:
        return screen_bounds_px_former(rel_m, self._half_axes_m[0], self._half_axes_m[1], camera.pixel_to_ray,
                                       state.width_px, state.height_px)


class FormerSceneRenderer(SceneRenderer):
    """:class:`psyop.session.scene_renderer.SceneRenderer` as it was before the frame caches: the whole scene
    built for each eye, every frame, moved into head space one primitive at a time; a :class:`FormerRenderer`."""

    def _frame_scene(self, row: TrialRow, phase: PhaseSpec, t_in_phase_s: float, eye: str,
                     head_pose: HeadPose | None, frame_scenes: dict[tuple[float, ...], Scene | None]) -> Scene | None:
        scene = self._scene(row, phase, t_in_phase_s, eye)
        if scene is None or head_pose is None or self._head_fixed(phase):
            return scene
        return scene_in_head_per_primitive(scene, *head_pose)

    def _make_renderer(self, scene: Scene) -> Renderer:
        return FormerRenderer(scene, settings=self.settings, ctx=self._ctx)


def depth_range_per_primitive_m(scene: Scene, point_m: np.ndarray) -> tuple[float, float]:
    """``Scene.depth_range_m`` one primitive at a time (the former per-frame path, the reference the vectorised
    form is tested against)."""
    if not scene.primitives:
        return (float("inf"), float("inf"))
    near = min(p.closest_distance_m(point_m) for p in scene.primitives)
    far = max(p.farthest_distance_m(point_m) for p in scene.primitives)
    return (near, far)


def screen_bounds_px_former(centres_rel_m: np.ndarray, half_u_m: np.ndarray, half_v_m: np.ndarray,
                            pixel_to_ray: np.ndarray, width_px: int, height_px: int) -> np.ndarray:
    """``screen_bounds_px`` as first written (more numpy calls, the same boxes bit for bit)."""
    c = np.asarray(centres_rel_m, dtype=np.float64).reshape(-1, 3)
    hu = np.asarray(half_u_m, dtype=np.float64).reshape(-1, 3)
    hv = np.asarray(half_v_m, dtype=np.float64).reshape(-1, 3)
    signs = np.array([[1.0, 1.0], [1.0, -1.0], [-1.0, 1.0], [-1.0, -1.0]])
    corners = c[:, None, :] + signs[None, :, :1] * hu[:, None, :] + signs[None, :, 1:] * hv[:, None, :]
    inv = np.linalg.inv(np.asarray(pixel_to_ray, dtype=np.float64))
    uvw = corners @ inv.T
    w = uvw[..., 2]
    in_front = np.all(w > 1e-12 * np.linalg.norm(corners, axis=-1), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = uvw[..., 0] / w * width_px
        y = uvw[..., 1] / w * height_px
    boxes = np.stack([x.min(axis=1), y.min(axis=1), x.max(axis=1), y.max(axis=1)], axis=-1)
    finite = in_front & np.all(np.isfinite(boxes), axis=1) & np.all(np.abs(boxes) < UNBOUNDED_PX, axis=1)
    boxes[~finite] = (-UNBOUNDED_PX, -UNBOUNDED_PX, UNBOUNDED_PX, UNBOUNDED_PX)
    return boxes


def scene_in_head_per_primitive(scene: Scene, head_position_m: Sequence[float],
                                head_orientation_wxyz: Sequence[float]) -> Scene:
    """``scene_in_head`` one primitive at a time (the former per-frame path)."""
    t = np.asarray(head_position_m, dtype=np.float64)
    if not np.any(t) and tuple(float(c) for c in head_orientation_wxyz) == IDENTITY_WXYZ:
        return scene
    r_t = rotation_matrix(head_orientation_wxyz).T
    primitives = tuple(
        dataclasses.replace(
            p,
            centre_m=tuple(rotate_rows(r_t, (np.asarray(p.centre_m) - (0.0 if p.at_infinity else t))[None])[0].tolist()),
            half_u_m=tuple(rotate_rows(r_t, np.asarray(p.half_u_m)[None])[0].tolist()),
            half_v_m=tuple(rotate_rows(r_t, np.asarray(p.half_v_m)[None])[0].tolist()),
        )
        for p in scene.primitives
    )
    return dataclasses.replace(scene, primitives=primitives, meshes=_moved_meshes(scene, t, head_orientation_wxyz))
