"""The mesh pass's per-frame drawing as it was before the per-frame CPU work was cut (issue 26 item 6):
kept for tests/rendering/test_mesh_frame_equality.py, which proves the current pass draws the same images.
Everything but :meth:`FormerMeshPass.draw` (the program, uploads, textures, targets) is the current MeshPass."""

from __future__ import annotations

import moderngl
import numpy as np

from psyop.mesh.asset import AlphaMode, Wrap
from psyop.optics.camera import EyeCamera
from psyop.rendering.mesh_data import MeshBatch
from psyop.rendering.mesh_pass import _ALPHA_CODE, MeshPass, MeshTarget, _GpuMesh, _u, instance_far_m, mesh_projection
from psyop.rendering.mesh_scene import MeshInstance


def visible_parts(part_corners: np.ndarray, clip_from_model: np.ndarray) -> np.ndarray:
    """(n parts,) bool: whether a part's bounding box can reach the view frustum (conservative: a box is
    culled only when all 8 corners lie outside one clip plane), one numpy product for all parts."""
    clip = part_corners @ clip_from_model.T  # (n, 8, 4)
    x, y, z, w = clip[..., 0], clip[..., 1], clip[..., 2], clip[..., 3]
    outside = ((x > w).all(-1) | (x < -w).all(-1) | (y > w).all(-1) | (y < -w).all(-1)
               | (z < -w).all(-1) | (z > w).all(-1))
    return ~outside


def draw_ranges(batch: MeshBatch, visible: np.ndarray) -> list[tuple[int, int]]:
    """(first, count) index ranges of ``batch`` to draw: one for the whole batch when all its parts are
    visible, else one per run of consecutive visible parts."""
    seen = visible[batch.part_index]
    if seen.all():
        return [(0, int(batch.indices.size))]
    ranges: list[tuple[int, int]] = []
    for first, count, ok in zip(batch.part_first.tolist(), batch.part_count.tolist(), seen.tolist(), strict=True):
        if not ok:
            continue
        if ranges and ranges[-1][0] + ranges[-1][1] == first:
            ranges[-1] = (ranges[-1][0], ranges[-1][1] + count)
        else:
            ranges.append((first, count))
    return ranges


class FormerMeshPass(MeshPass):
    """MeshPass with the former draw: uniforms looked up and written for every batch of every eye, the model
    matrix, normal matrix and far plane computed per eye, the visible runs found part by part."""

    def draw(self, target: MeshTarget, camera: EyeCamera, instances: tuple[MeshInstance, ...]) -> int:
        """Rasterise ``instances`` into ``target`` with ``camera``; returns how many parts were drawn."""
        ctx = self.ctx
        target.fbo.use()
        ctx.viewport = (0, 0, *target.size)
        target.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        view = np.asarray(camera.view, dtype=np.float64)
        cop = np.asarray(camera.centre_of_projection_m, dtype=np.float64)
        proj = mesh_projection(camera, instance_far_m(instances, cop))
        _u(self.program, "u_projection").write(proj.astype(np.float32).T.tobytes())
        drawn = 0
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.depth_func = "<"
        ctx.front_face = "ccw"
        try:
            passes = (False, True)  # every instance's opaque and mask batches, then every BLEND batch
            uploaded = [(inst, self._upload(inst.asset)) for inst in instances]
            for blend_pass in passes:
                for inst, gpu in uploaded:
                    drawn += self._draw_instance(inst, gpu, view, proj, blend_pass)
        finally:
            ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE | moderngl.BLEND)
            ctx.fbo.depth_mask = True
        return drawn

    def _draw_instance(self, inst: MeshInstance, gpu: _GpuMesh, view: np.ndarray, proj: np.ndarray,
                       blend_pass: bool) -> int:
        ctx = self.ctx
        prog = self.program
        shift = np.eye(4)
        shift[:3, 3] = gpu.prepared.origin_m
        model_view = view @ inst.model @ shift  # float64: the centre of projection is subtracted here
        visible = visible_parts(gpu.prepared.part_corners, proj @ model_view)
        if not visible.any():
            return 0
        linear = model_view[:3, :3]
        normal_matrix = np.linalg.inv(linear).T
        _u(prog, "u_model_view").write(model_view.astype(np.float32).T.tobytes())
        _u(prog, "u_normal_matrix").write(normal_matrix.astype(np.float32).T.tobytes())
        lambert = inst.shading == "lambert"
        _u(prog, "u_lambert").value = lambert
        if lambert:
            light = view[:3, :3] @ np.asarray(inst.light_direction, dtype=np.float64)
            _u(prog, "u_light_eye").value = tuple(float(v) for v in light / np.linalg.norm(light))
            _u(prog, "u_ambient").value = float(inst.ambient)
        drawn = 0
        for gb in gpu.batches:
            batch = gb.batch
            if (batch.alpha_mode is AlphaMode.BLEND) != blend_pass:
                continue
            ranges = draw_ranges(batch, visible)
            if not ranges:
                continue
            if batch.double_sided:
                ctx.disable(moderngl.CULL_FACE)
            else:
                ctx.enable(moderngl.CULL_FACE)
            if blend_pass:
                ctx.enable(moderngl.BLEND)
                ctx.blend_func = moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA  # premultiplied "over"
                ctx.fbo.depth_mask = False
            else:
                ctx.disable(moderngl.BLEND)
                ctx.fbo.depth_mask = True
            _u(prog, "u_alpha_mode").value = _ALPHA_CODE[batch.alpha_mode]
            _u(prog, "u_alpha_cutoff").value = float(batch.alpha_cutoff)
            _u(prog, "u_has_normals").value = bool(batch.has_normals)
            _u(prog, "u_has_texture").value = gb.texture is not None
            if gb.texture is not None:
                tex = batch.texture
                assert tex is not None
                _u(prog, "u_mirror").value = (int(tex.wrap_s is Wrap.MIRROR), int(tex.wrap_t is Wrap.MIRROR))
                gb.texture.use(5)
            for first, count in ranges:
                gb.vao.render(moderngl.TRIANGLES, vertices=count, first=first)
                self.draws += 1
            drawn += int(visible[batch.part_index].sum())
        return drawn
