"""The rasterising pass for mesh items (glTF models), drawn with the ray-caster's own per-eye camera.

Per eye and frame, before the analytic ray-cast (docs/rendering.md, "Meshes"):

1. Every :class:`psyop.rendering.mesh_scene.MeshInstance` is rasterised into the eye's multisampled
   mesh target (:data:`MESH_MSAA_SAMPLES` samples, the same on every display): a premultiplied linear
   RGBA colour and, per sample, the reciprocal of the fragment's Euclidean distance from the centre of
   projection (0 = no mesh), with a depth buffer for mesh-against-mesh occlusion.
2. The ray-caster (compiled with ``MESH_LAYER``, psyop.rendering.shaders) reads both textures: each of
   its ray samples compares its analytic hit distance with the nearest mesh distance in the pixel and
   shows the analytic surface where it is nearer, else the mesh's resolved colour over it. So meshes and
   analytic primitives share one depth (distance from the same centre of projection) and occlude each
   other per ray sample.

The camera is exactly the ray-caster's ``EyeCamera``: ``view`` (camera-relative: the translation by the
centre of projection is folded into the model-view matrix in float64, then cast to float32) and the x/y
rows of ``projection`` (the off-axis frustum of the display or of the OpenXR view, any mode), with the
depth row's far plane raised to the meshes' extent. Static data (vertex, index and texture buffers) is
uploaded once per asset (:func:`psyop.rendering.mesh_data.prepare_mesh`); per frame only matrices change,
and parts whose bounding box lies outside the eye's frustum are skipped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import cast

import moderngl
import numpy as np

from psyop.mesh.asset import AlphaMode, Filter, MeshAsset, MeshTexture, Wrap
from psyop.optics.camera import EyeCamera
from psyop.rendering.camera_math import near_far_m
from psyop.rendering.mesh_data import (
    MeshBatch,
    PreparedMesh,
    draw_ranges,
    prepare_mesh,
    visible_parts,
)
from psyop.rendering.mesh_scene import MeshInstance

#: Multisample anti-aliasing of the mesh pass: 4 samples per pixel on every display (llvmpipe's maximum,
#: and the count every desktop GPU offers), so images agree across displays.
MESH_MSAA_SAMPLES = 4

MESH_VERTEX_SHADER = """
#version 410 core
in vec3 in_position;
in vec3 in_normal;
in vec2 in_texcoord;
in vec4 in_colour;
uniform mat4 u_model_view;   // model (origin-relative) -> camera-relative eye space, float64 made float32
uniform mat4 u_projection;
uniform mat3 u_normal_matrix;
out vec3 v_eye;
out vec3 v_normal;
out vec2 v_texcoord;
out vec4 v_colour;
void main() {
    vec4 eye = u_model_view * vec4(in_position, 1.0);
    v_eye = eye.xyz;
    v_normal = u_normal_matrix * in_normal;
    v_texcoord = in_texcoord;
    v_colour = in_colour;
    gl_Position = u_projection * eye;
}
"""

MESH_FRAGMENT_SHADER = """
#version 410 core
in vec3 v_eye;
in vec3 v_normal;
in vec2 v_texcoord;
in vec4 v_colour;
uniform sampler2D u_texture;
uniform bool u_has_texture;
uniform ivec2 u_mirror;       // per axis: 1 = MIRRORED_REPEAT (the sampler clamps, the shader mirrors)
uniform int u_alpha_mode;     // 0 OPAQUE, 1 MASK, 2 BLEND
uniform float u_alpha_cutoff;
uniform bool u_lambert;
uniform bool u_has_normals;
uniform vec3 u_light_eye;     // unit vector towards the light, eye space
uniform float u_ambient;
layout(location = 0) out vec4 out_colour;    // premultiplied linear RGBA
layout(location = 1) out vec4 out_inv_dist;  // 1 / distance from the centre of projection (alpha 1: replaces)
void main() {
    vec4 c = v_colour;
    if (u_has_texture) {
        vec2 st = v_texcoord;
        if (u_mirror.x == 1) st.x = 1.0 - abs(mod(st.x, 2.0) - 1.0);
        if (u_mirror.y == 1) st.y = 1.0 - abs(mod(st.y, 2.0) - 1.0);
        c *= textureGrad(u_texture, st, dFdx(v_texcoord), dFdy(v_texcoord));
    }
    if (u_alpha_mode == 1 && c.a < u_alpha_cutoff) discard;
    if (u_alpha_mode != 2) c.a = 1.0;
    if (u_lambert) {
        vec3 n = u_has_normals ? normalize(v_normal) : normalize(cross(dFdx(v_eye), dFdy(v_eye)));
        if (dot(n, v_eye) > 0.0) n = -n;  // the side that faces the viewer
        c.rgb *= u_ambient + (1.0 - u_ambient) * max(dot(n, u_light_eye), 0.0);
    }
    out_colour = vec4(clamp(c.rgb, 0.0, 1.0) * c.a, c.a);
    out_inv_dist = vec4(1.0 / length(v_eye), 0.0, 0.0, 1.0);
}
"""

_ALPHA_CODE = {AlphaMode.OPAQUE: 0, AlphaMode.MASK: 1, AlphaMode.BLEND: 2}
_MIN_FILTER = {Filter.NEAREST: moderngl.NEAREST, Filter.LINEAR: moderngl.LINEAR,
               Filter.LINEAR_MIPMAP: moderngl.LINEAR_MIPMAP_LINEAR}
_MAG_FILTER = {Filter.NEAREST: moderngl.NEAREST, Filter.LINEAR: moderngl.LINEAR, Filter.LINEAR_MIPMAP: moderngl.LINEAR}



def _u(program: moderngl.Program, name: str) -> moderngl.Uniform:
    """The program's uniform ``name`` (moderngl types a member lookup as any kind of member)."""
    return cast(moderngl.Uniform, program[name])

def mesh_projection(camera: EyeCamera, far_m: float) -> np.ndarray:
    """The camera's projection with its depth row spanning [the camera's near, ``far_m``] (x, y and w rows
    untouched: the same off-axis frustum as the ray-caster's pixel rays)."""
    near, cam_far = near_far_m(camera)
    near = near if near > 0 else 0.01
    far = max(float(far_m), cam_far if math.isfinite(cam_far) else 0.0, 2.0 * near)
    proj = np.array(camera.projection, dtype=np.float64)
    proj[2] = (0.0, 0.0, -(far + near) / (far - near), -2.0 * far * near / (far - near))
    return proj


def instance_far_m(instances: tuple[MeshInstance, ...], cop: np.ndarray) -> float:
    """A far plane beyond every instance's bounding sphere, seen from ``cop``."""
    return spheres_far_m([inst.bounding_sphere_m() for inst in instances], cop)


def spheres_far_m(spheres: list[tuple[np.ndarray, float]], cop: np.ndarray) -> float:
    """:func:`instance_far_m` from the instances' bounding spheres (centre, radius), computed once per frame."""
    far = 0.0
    for centre, radius in spheres:
        far = max(far, float(np.linalg.norm(centre - cop)) + radius)
    return 1.01 * far + 1e-3


@dataclass
class _GpuBatch:
    batch: MeshBatch
    vao: moderngl.VertexArray
    buffers: list[moderngl.Buffer]
    texture: moderngl.Texture | None
    #: the batch's material uniforms (name, value), fixed when it is uploaded
    uniforms: tuple[tuple[str, object], ...] = ()


@dataclass
class _GpuMesh:
    prepared: PreparedMesh
    batches: list[_GpuBatch]
    shift: np.ndarray  # (4, 4) float64: the batches' origin (PreparedMesh.origin_m) back into model units


@dataclass
class _FrameInstance:
    """What the pass needs of one instance, computed once for the eyes of a frame that share its scene."""

    instance: MeshInstance
    gpu: _GpuMesh
    model: np.ndarray  # (4, 4) float64
    sphere: tuple[np.ndarray, float]  # MeshInstance.bounding_sphere_m


def _material_uniforms(batch: MeshBatch) -> tuple[tuple[str, object], ...]:
    """The uniforms of a batch's material state (written only when they differ from the program's)."""
    values: list[tuple[str, object]] = [("u_alpha_mode", _ALPHA_CODE[batch.alpha_mode]),
                                        ("u_alpha_cutoff", float(batch.alpha_cutoff)),
                                        ("u_has_normals", bool(batch.has_normals)),
                                        ("u_has_texture", batch.texture is not None)]
    if batch.texture is not None:
        values.append(("u_mirror", (int(batch.texture.wrap_s is Wrap.MIRROR), int(batch.texture.wrap_t is Wrap.MIRROR))))
    return tuple(values)


@dataclass
class MeshTarget:
    """One eye's multisampled mesh target: colour and reciprocal distance textures, depth, framebuffer."""

    size: tuple[int, int]
    colour: moderngl.Texture
    inv_distance: moderngl.Texture
    depth: moderngl.Renderbuffer
    fbo: moderngl.Framebuffer

    def release(self) -> None:
        for obj in (self.fbo, self.colour, self.inv_distance, self.depth):
            obj.release()


@dataclass
class MeshPass:
    """GL resources of the mesh pass on one context: the program, each asset's buffers (uploaded once,
    keyed by the asset object) and the textures (one upload per content key)."""

    ctx: moderngl.Context
    program: moderngl.Program = field(init=False)
    meshes: dict[int, tuple[MeshAsset, _GpuMesh]] = field(default_factory=dict)
    textures: dict[str, moderngl.Texture] = field(default_factory=dict)
    draws: int = 0  # draw calls issued (tests and benchmarks)
    _uniforms: dict[str, moderngl.Uniform] = field(default_factory=dict)  # the program's, looked up once
    _written: dict[str, object] = field(default_factory=dict)  # the value each scalar uniform holds
    _frame: tuple[tuple[MeshInstance, ...], list[_FrameInstance]] | None = None  # the last instances' data

    def __post_init__(self) -> None:
        self.program = self.ctx.program(vertex_shader=MESH_VERTEX_SHADER, fragment_shader=MESH_FRAGMENT_SHADER)
        _u(self.program, "u_texture").value = 5
        for name in ("u_model_view", "u_projection", "u_normal_matrix", "u_alpha_mode", "u_alpha_cutoff",
                     "u_has_normals", "u_has_texture", "u_mirror", "u_lambert", "u_light_eye", "u_ambient"):
            if name in self.program:  # the GLSL compiler drops a uniform no output depends on
                self._uniforms[name] = _u(self.program, name)

    def _set(self, name: str, value: object) -> None:
        """Write a scalar or vector uniform unless the program holds that value already."""
        if self._written.get(name, self) != value:
            self._uniforms[name].value = value
            self._written[name] = value

    @property
    def samples(self) -> int:
        return min(MESH_MSAA_SAMPLES, int(self.ctx.max_samples))

    def target(self, width_px: int, height_px: int) -> MeshTarget:
        size = (int(width_px), int(height_px))
        colour = self.ctx.texture(size, 4, samples=self.samples, dtype="f4")
        inv = self.ctx.texture(size, 1, samples=self.samples, dtype="f4")
        depth = self.ctx.depth_renderbuffer(size, samples=self.samples)
        fbo = self.ctx.framebuffer(color_attachments=[colour, inv], depth_attachment=depth)
        return MeshTarget(size, colour, inv, depth, fbo)

    def _texture(self, tex: MeshTexture) -> moderngl.Texture:
        gl = self.textures.get(tex.key)
        if gl is None:
            pixels = np.ascontiguousarray(tex.rgba_linear, dtype=np.float32)
            h, w = pixels.shape[:2]
            gl = self.ctx.texture((w, h), 4, pixels.tobytes(), dtype="f4")  # row 0 = the image's top row = v 0
            if tex.min_filter is Filter.LINEAR_MIPMAP:
                gl.build_mipmaps()
            gl.filter = (_MIN_FILTER[tex.min_filter], _MAG_FILTER[tex.mag_filter])
            gl.repeat_x = tex.wrap_s is Wrap.REPEAT
            gl.repeat_y = tex.wrap_t is Wrap.REPEAT
            self.textures[tex.key] = gl
        return gl

    def _upload(self, asset: MeshAsset) -> _GpuMesh:
        entry = self.meshes.get(id(asset))
        if entry is not None and entry[0] is asset:
            return entry[1]
        prepared = prepare_mesh(asset)
        batches = []
        for batch in prepared.batches:
            vbo = self.ctx.buffer(batch.vertices.astype(np.float32).tobytes())
            ibo = self.ctx.buffer(batch.indices.astype(np.uint32).tobytes())
            vao = self.ctx.vertex_array(self.program, [(vbo, "3f 3f 2f 4f", "in_position", "in_normal", "in_texcoord",
                                                        "in_colour")], index_buffer=ibo, index_element_size=4)
            texture = None if batch.texture is None else self._texture(batch.texture)
            batches.append(_GpuBatch(batch, vao, [vbo, ibo], texture, _material_uniforms(batch)))
        shift = np.eye(4)
        shift[:3, 3] = prepared.origin_m
        gpu = _GpuMesh(prepared, batches, shift)
        self.meshes[id(asset)] = (asset, gpu)  # the asset is kept alive with its buffers: ids stay unique
        return gpu

    def _frame_instances(self, instances: tuple[MeshInstance, ...]) -> list[_FrameInstance]:
        """Each instance's upload, model matrix and bounding sphere: computed once for the same instances
        tuple (both eyes of a frame share their scene; a scene that does not move shares it across frames)."""
        if self._frame is not None and self._frame[0] is instances:
            return self._frame[1]
        data = [_FrameInstance(inst, self._upload(inst.asset), inst.model, inst.bounding_sphere_m()) for inst in instances]
        self._frame = (instances, data)
        return data

    def draw(self, target: MeshTarget, camera: EyeCamera, instances: tuple[MeshInstance, ...]) -> int:
        """Rasterise ``instances`` into ``target`` with ``camera``; returns how many parts were drawn.

        Per eye this is numpy on 4x4 matrices and one frustum test per instance (all parts in one product),
        then a few uniform writes and one draw per material batch (or per run of visible parts): no Python
        loop over nodes or triangles."""
        ctx = self.ctx
        target.fbo.use()
        ctx.viewport = (0, 0, *target.size)
        target.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        view = np.asarray(camera.view, dtype=np.float64)
        cop = np.asarray(camera.centre_of_projection_m, dtype=np.float64)
        frame = self._frame_instances(instances)
        proj = mesh_projection(camera, spheres_far_m([f.sphere for f in frame], cop))
        self._uniforms["u_projection"].write(proj.astype(np.float32).T.tobytes())
        drawn = 0
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.depth_func = "<"
        ctx.front_face = "ccw"
        try:
            visible = [self._visible(f, view, proj) for f in frame]
            for blend_pass in (False, True):  # every instance's opaque and mask batches, then every BLEND batch
                for f, (model_view, seen) in zip(frame, visible, strict=True):
                    if seen is not None:
                        drawn += self._draw_instance(f, model_view, seen, view, blend_pass)
        finally:
            ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE | moderngl.BLEND)
            ctx.fbo.depth_mask = True
        return drawn

    @staticmethod
    def _visible(f: _FrameInstance, view: np.ndarray, proj: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """The instance's model-view matrix (float64: the centre of projection is subtracted here) and its
        parts' visibility (None: no part reaches the eye's frustum)."""
        model_view = view @ f.model @ f.gpu.shift
        visible = visible_parts(f.gpu.prepared.part_corners, proj @ model_view)
        return model_view, (visible if visible.any() else None)

    def _instance_uniforms(self, f: _FrameInstance, model_view: np.ndarray, view: np.ndarray) -> None:
        """The instance's matrices and shading; the normal matrix and light only where lambert shading reads them."""
        inst = f.instance
        self._uniforms["u_model_view"].write(model_view.astype(np.float32).T.tobytes())
        lambert = inst.shading == "lambert"
        self._set("u_lambert", lambert)
        if lambert:
            normal_matrix = np.linalg.inv(model_view[:3, :3]).T
            self._uniforms["u_normal_matrix"].write(normal_matrix.astype(np.float32).T.tobytes())
            light = view[:3, :3] @ np.asarray(inst.light_direction, dtype=np.float64)
            self._set("u_light_eye", tuple(float(v) for v in light / np.linalg.norm(light)))
            self._set("u_ambient", float(inst.ambient))

    def _draw_instance(self, f: _FrameInstance, model_view: np.ndarray, visible: np.ndarray, view: np.ndarray,
                       blend_pass: bool) -> int:
        ctx = self.ctx
        batches = [gb for gb in f.gpu.batches if (gb.batch.alpha_mode is AlphaMode.BLEND) == blend_pass]
        if not batches:
            return 0
        self._instance_uniforms(f, model_view, view)
        drawn = 0
        for gb in batches:
            seen = visible[gb.batch.part_index]
            ranges = draw_ranges(gb.batch, seen)
            if not ranges:
                continue
            if gb.batch.double_sided:
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
            for name, value in gb.uniforms:
                self._set(name, value)
            if gb.texture is not None:
                gb.texture.use(5)
            for first, count in ranges:
                gb.vao.render(moderngl.TRIANGLES, vertices=count, first=first)
                self.draws += 1
            drawn += int(seen.sum())
        return drawn


    def release(self) -> None:
        for _, gpu in self.meshes.values():
            for gb in gpu.batches:
                gb.vao.release()
                for buf in gb.buffers:
                    buf.release()
        for tex in self.textures.values():
            tex.release()
        self.meshes.clear()
        self.textures.clear()
        self.program.release()
