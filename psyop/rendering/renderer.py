"""The moderngl ray-casting renderer: a :class:`Scene` plus an ``EyeCamera`` -> an image.

Static data (primitive axes, materials, textures, the screen-fixed aperture mask) is uploaded
once; per frame only uniforms change: the pixel-to-ray matrix and the primitives' centres
relative to the centre of projection, computed in float64 on the CPU so millimetre shifts of the
centre survive the float32 GPU arithmetic. One off-screen float framebuffer per eye; monocular
rendering simply never touches the other eye.

Invalid cameras (``valid`` False, NaN/inf numbers) never reach the GPU: the eye keeps its last
valid camera (or shows the background if it never had one) and the frame is counted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import moderngl
import numpy as np

from psyop.rendering.camera_math import camera_is_usable, near_far_m, pixel_rays
from psyop.rendering.reuse import ReuseDecision, decide_reuse
from psyop.rendering.scene import (
    Grating,
    GridMaterial,
    ImageTexture,
    OUTPUT_TABLE_ROW,
    NoiseTexture,
    OutputTransfer,
    Scene,
    Shape,
    Solid,
    Waveform,
    WindowKind,
)
from psyop.rendering.shaders import (
    MAX_PRIMITIVES,
    OUTPUT_FRAGMENT_SHADER,
    TEXELS_PER_PRIMITIVE,
    VERTEX_SHADER,
    AntiAliasing,
    edge_pass_shader,
    fragment_shader,
)
from psyop.rendering.screen_bounds import screen_bounds_px
from psyop.rendering.textures import pack_layers, texture_pixels

if TYPE_CHECKING:
    from psyop.optics.camera import EyeCamera
    from psyop.rendering.mesh_pass import MeshPass, MeshTarget
    from psyop.rendering.scene import Primitive

    # the ray-cast and edge programs and their vertex arrays (edge ones absent without the two-pass edge)
    _Variant = tuple[moderngl.Program, moderngl.Program | None, moderngl.VertexArray, moderngl.VertexArray | None]


@dataclass(frozen=True)
class RenderSettings:
    """How to render. ``reuse_tolerance_px`` None disables frame reuse."""

    antialiasing: AntiAliasing = AntiAliasing.ADAPTIVE
    samples_per_axis: int = 32
    msaa_samples: int = 4
    edge_margin_px: float = 1.0
    reuse_tolerance_px: float | None = 0.01
    # Adaptive only: supersample edge pixels in a second, depth-tested pass (default) rather than
    # in place (the original single-pass form, kept for the side-by-side benchmark).
    adaptive_two_pass: bool = True
    # Two-pass only: the first pass skips primitives whose conservative screen box misses the
    # pixel's 4x4 block (same image; kept switchable to measure what it saves).
    adaptive_cull: bool = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "antialiasing", AntiAliasing(self.antialiasing))
        if not 1 <= self.samples_per_axis <= 64:
            raise ValueError(f"samples_per_axis must be in [1, 64], got {self.samples_per_axis}")


@dataclass(frozen=True)
class FrameResult:
    """What happened to one requested frame."""

    eye: str
    rendered: bool
    camera_usable: bool
    camera_used: EyeCamera | None
    reuse: ReuseDecision | None


@dataclass
class RenderStats:
    """Counters over the renderer's lifetime (per instance)."""

    frames_requested: int = 0
    frames_rendered: int = 0
    frames_skipped: int = 0
    invalid_cameras: int = 0
    largest_skipped_bound_px: float = 0.0


@dataclass
class _EyeState:
    width_px: int
    height_px: int
    fbo: moderngl.Framebuffer
    colour: moderngl.Texture
    msaa_fbo: moderngl.Framebuffer | None
    aperture: moderngl.Texture | None
    depth: moderngl.Renderbuffer | None = None
    mesh_target: MeshTarget | None = None  # the mesh pass's multisampled target (psyop.rendering.mesh_pass), when drawn
    last_valid_camera: EyeCamera | None = None
    last_rendered_camera: EyeCamera | None = None
    depth_range_m: tuple[float, float] | None = (0.0, math.inf)  # None: not computed yet (see depth_centre_m)
    depth_centre_m: np.ndarray | None = None  # the centre of projection of the last image, for depth_range_m
    rendered_scene: Scene | None = None  # the scene of this eye's last image (reuse needs the same)
    # a calibrated display's ray-cast target (normalised luminance; the final pass maps it into ``fbo``)
    linear: moderngl.Texture | None = None
    linear_fbo: moderngl.Framebuffer | None = None
    frames_output: int = 0  # final passes drawn for this eye (the dither's frame index)
    released: list[Any] = field(default_factory=list)  # Any: moderngl objects of any kind, released together


def _eye_key(camera: EyeCamera) -> str:
    eye = getattr(camera, "eye", "right")
    return str(getattr(eye, "value", eye))


def _finite_extent_m(scene: Scene) -> float:
    """An upper bound on the distance from the head origin to any point of a finite primitive
    (the far clip is raised to it, so a far but finite surface is never dropped)."""
    finite = [p for p in scene.primitives if not p.at_infinity]
    if not finite:
        return 0.0
    c, u, v = (np.array([getattr(p, a) for p in finite], dtype=np.float64) for a in ("centre_m", "half_u_m", "half_v_m"))
    return 1.001 * float(np.max(_row_norms(c) + _row_norms(u) + _row_norms(v)))


def _row_norms(x: np.ndarray) -> np.ndarray:
    """Row-wise Euclidean norms of an (n, 3) array, rounded like ``np.linalg.norm`` of each row."""
    return np.sqrt((x[:, None, :] @ x[:, :, None])[:, 0, 0])


def create_headless_context() -> moderngl.Context:
    """A standalone OpenGL context via EGL (no display needed)."""
    settings: dict[str, Any] = {"backend": "egl"}  # Any: moderngl's stub types each setting as a dict
    return moderngl.create_standalone_context(**settings)


def _uniform(prog: moderngl.Program, name: str) -> moderngl.Uniform:
    """The program's uniform ``name`` (moderngl types a member lookup as any kind of member)."""
    member = prog[name]
    if not isinstance(member, moderngl.Uniform):
        raise TypeError(f"the shader's '{name}' is a {type(member).__name__}, not a uniform")
    return member


def _block(prog: moderngl.Program, name: str) -> moderngl.UniformBlock:
    """The program's uniform block ``name``."""
    member = prog[name]
    if not isinstance(member, moderngl.UniformBlock):
        raise TypeError(f"the shader's '{name}' is a {type(member).__name__}, not a uniform block")
    return member


class Renderer:
    """Ray-casts a scene for one or two eyes. Use as a context manager or call :meth:`release`."""

    def __init__(self, scene: Scene, settings: RenderSettings | None = None, ctx: moderngl.Context | None = None):
        self.settings = settings or RenderSettings()
        self._owns_ctx = ctx is None
        self.ctx = ctx if ctx is not None else create_headless_context()
        self.stats = RenderStats()
        self._eyes: dict[str, _EyeState] = {}
        self._two_pass = (self.settings.antialiasing is AntiAliasing.ADAPTIVE and self.settings.adaptive_two_pass)
        self._prog = self.ctx.program(vertex_shader=VERTEX_SHADER,
                                      fragment_shader=fragment_shader(self.settings.antialiasing, self._two_pass,
                                                                      self.settings.adaptive_cull))
        self._vao = self.ctx.vertex_array(self._prog, [])
        self._centres = self.ctx.buffer(reserve=MAX_PRIMITIVES * 16)
        self._edge_prog: moderngl.Program | None = None
        self._edge_vao: moderngl.VertexArray | None = None
        self._bounds: moderngl.Buffer | None = None
        if self._two_pass:
            self._edge_prog = self.ctx.program(vertex_shader=VERTEX_SHADER, fragment_shader=edge_pass_shader())
            self._edge_vao = self.ctx.vertex_array(self._edge_prog, [])
            self._bounds = self.ctx.buffer(reserve=MAX_PRIMITIVES * 16)
        self._prims_tex: moderngl.Texture | None = None
        self._layers_tex: moderngl.TextureArray | None = None
        self._packed: dict[int, tuple[Primitive, int | None, list[float]]] = {}  # id(primitive) -> (it, layer, row)
        self._texture_keys: tuple[NoiseTexture | tuple[str, str], ...] = ()
        self._texture_sizes: list[tuple[int, int]] = []
        self._scene: Scene | None = None
        self._uniform_values: dict[str, Any] = {}  # Any: GL uniform value; last written per uniform
        self._member_names: dict[int, frozenset[str]] = {}
        # the ray-cast programs without and (compiled on first use) with the mesh layer, and the mesh pass
        self._variants: dict[bool, _Variant] = {
            False: (self._prog, self._edge_prog, self._vao, self._edge_vao)}
        self._with_meshes = False
        self._mesh_pass: MeshPass | None = None
        # the final pass of a calibrated display (psyop.rendering.scene.OutputTransfer), built on first use
        self._output: OutputTransfer | None = None
        self._output_prog: moderngl.Program | None = None
        self._output_vao: moderngl.VertexArray | None = None
        self._table_tex: moderngl.Texture | None = None
        self._set_constant_uniforms()  # uniforms no frame changes: written once
        self.set_scene(scene)

    def _set_constant_uniforms(self) -> None:
        for prog in self._programs():
            _block(prog, "Centres").binding = 0
            _uniform(prog, "u_prims").value = 0
            _uniform(prog, "u_textures").value = 1
            _uniform(prog, "u_aperture").value = 2
        if self._edge_prog is not None:  # two-pass
            _block(self._edge_prog, "Bounds").binding = 1
            if "Bounds" in self._members(self._prog):
                _block(self._prog, "Bounds").binding = 1

    # -- scene upload (once per scene) ----------------------------------------------------------
    def set_scene(self, scene: Scene) -> None:
        """Upload a scene's static data.

        An equal scene is a no-op. Frame reuse is per eye: an eye reuses its last image only if
        it was rendered from a scene equal to the current one, so a stereo session that sets
        each eye's scene in turn keeps reusing both eyes' frames. Textures are re-synthesised and
        re-uploaded only when the set of texture materials changes, so a session can call this
        every frame (e.g. for a moving fixation target) at the cost of a few hundred bytes.
        """
        if scene is self._scene or scene == self._scene:
            return
        if bool(scene.meshes) != self._with_meshes:
            self._use_variant(bool(scene.meshes))
        if len(scene.primitives) > MAX_PRIMITIVES:
            raise ValueError(f"at most {MAX_PRIMITIVES} primitives, got {len(scene.primitives)}")
        layer_of = self._upload_textures(scene)
        self._upload_primitives(scene, layer_of)
        if scene.output != self._output:
            self._set_output(scene.output)
        aperture_changed = self._scene is None or scene.aperture != self._scene.aperture
        self._scene = scene
        for state in self._eyes.values():
            if aperture_changed:  # the aperture is screen-fixed: recomputed only when it changes
                self._release_eye_aperture(state)
                state.aperture = None
        self._set_scene_uniforms(scene)

    def _set_scene_uniforms(self, scene: Scene) -> None:
        """The scene's uniforms: primitive count, background, aperture colour and sampling settings."""
        ap_colour = scene.aperture.colour if scene.aperture else (0.0, 0.0, 0.0)
        self._set_if_present("u_n_prims", len(scene.primitives))
        self._set_if_present("u_background", scene.background)
        self._set_if_present("u_aperture_colour", ap_colour)
        self._set_if_present("u_samples", int(self.settings.samples_per_axis))
        self._set_if_present("u_edge_margin_px", float(self.settings.edge_margin_px))

    def _set_output(self, output: OutputTransfer | None) -> None:
        """Switch the final pass on (a calibrated display: upload its table) or off (values written as they are)."""
        self._output = output
        if self._table_tex is not None:
            self._table_tex.release()
            self._table_tex = None
        for state in self._eyes.values():
            self._release_linear(state)
        if output is None:
            return
        if self._output_prog is None:
            self._output_prog = self.ctx.program(vertex_shader=VERTEX_SHADER, fragment_shader=OUTPUT_FRAGMENT_SHADER)
            self._output_vao = self.ctx.vertex_array(self._output_prog, [])
            _uniform(self._output_prog, "u_linear").value = 5
            _uniform(self._output_prog, "u_table").value = 6
        n = output.table.shape[0]
        rows = -(-n // OUTPUT_TABLE_ROW)
        table = np.zeros((rows * OUTPUT_TABLE_ROW, 4), dtype=np.float32)
        table[:n, :3] = output.table
        self._table_tex = self.ctx.texture((OUTPUT_TABLE_ROW, rows), 4, table.tobytes(), dtype="f4")
        self._table_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        _uniform(self._output_prog, "u_table_size").value = int(output.table.shape[0])
        _uniform(self._output_prog, "u_dither").value = 1 if output.dither else 0

    def _release_linear(self, state: _EyeState) -> None:
        for obj in (state.linear_fbo, state.linear):
            if obj is not None:
                obj.release()
        state.linear = state.linear_fbo = None

    def _linear_target(self, state: _EyeState) -> moderngl.Framebuffer:
        """The eye's ray-cast target on a calibrated display (float, with the two-pass depth), made on first use."""
        if state.linear_fbo is None:
            state.linear = self.ctx.texture((state.width_px, state.height_px), 4, dtype="f4")
            state.linear.filter = (moderngl.NEAREST, moderngl.NEAREST)
            state.linear_fbo = self.ctx.framebuffer(color_attachments=[state.linear], depth_attachment=state.depth)
        return state.linear_fbo

    def _final_pass(self, state: _EyeState) -> None:
        """Normalised luminance -> codes (the calibration's inverse and the dither), into the eye's image."""
        assert self._output_vao is not None and self._output_prog is not None and self._table_tex is not None
        assert state.linear is not None
        state.fbo.use()
        self.ctx.viewport = (0, 0, state.width_px, state.height_px)
        state.linear.use(5)
        self._table_tex.use(6)
        _uniform(self._output_prog, "u_offset").value = float((state.frames_output * 0.6180339887498949) % 1.0)
        state.frames_output += 1
        self._output_vao.render(moderngl.TRIANGLES, vertices=3)

    def _upload_textures(self, scene: Scene) -> dict[NoiseTexture | tuple[str, str], int]:
        """The texture layer of each texture material of ``scene``; the layers are re-synthesised and
        re-uploaded only when the set of texture materials changes."""
        textures: list[NoiseTexture | ImageTexture] = []
        layer_of: dict[NoiseTexture | tuple[str, str], int] = {}
        for p in scene.primitives:
            if isinstance(p.material, (NoiseTexture, ImageTexture)):
                key = p.material if isinstance(p.material, NoiseTexture) else ("image", p.material.key)
                if key not in layer_of:
                    layer_of[key] = len(textures)
                    textures.append(p.material)
        texture_keys = tuple(layer_of)
        if texture_keys != self._texture_keys or self._layers_tex is None:
            self._packed = {}  # rows name texture layers: repacked for the new set
            layers, sizes = pack_layers([texture_pixels(t) for t in textures])
            if self._layers_tex is not None:
                self._layers_tex.release()
            side = layers.shape[1]
            layers_tex = self.ctx.texture_array((side, side, layers.shape[0]), 4, layers.tobytes(), dtype="f4")
            layers_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._layers_tex = layers_tex
            self._texture_keys, self._texture_sizes = texture_keys, sizes
        return layer_of

    def _upload_primitives(self, scene: Scene, layer_of: dict[NoiseTexture | tuple[str, str], int]) -> None:
        """Pack ``scene``'s primitives into the primitive texture and keep their head-space geometry."""
        sizes = self._texture_sizes
        data = np.zeros((max(1, len(scene.primitives)), TEXELS_PER_PRIMITIVE, 4), dtype=np.float32)
        n = len(scene.primitives)
        self._centres_head = np.array([p.centre_m for p in scene.primitives], dtype=np.float64).reshape(n, 3)
        self._half_axes_m = np.array([[p.half_u_m for p in scene.primitives], [p.half_v_m for p in scene.primitives]],
                                     dtype=np.float64).reshape(2, n, 3)
        # w of each centre: 1 = a point (made camera-relative), 0 = a direction (optical infinity)
        self._centre_w = np.array([0.0 if p.at_infinity else 1.0 for p in scene.primitives])
        self._scene_far_m = _finite_extent_m(scene)
        packed: dict[int, tuple[Primitive, int | None, list[float]]] = {}
        rows = []
        for p in scene.primitives:
            m = p.material
            layer = layer_of[m if isinstance(m, NoiseTexture) else ("image", m.key)] \
                if isinstance(m, (NoiseTexture, ImageTexture)) else None
            entry = self._packed.get(id(p))
            if entry is None or entry[0] is not p or entry[1] != layer:
                entry = (p, layer, self._pack(p, layer, sizes))
            packed[id(p)] = entry  # only the current scene's primitives stay cached
            rows.append(entry[2])
        if rows:
            data[:n] = np.array(rows, dtype=np.float32).reshape(n, TEXELS_PER_PRIMITIVE, 4)
        self._packed = packed
        if self._prims_tex is not None and self._prims_tex.size == (TEXELS_PER_PRIMITIVE, data.shape[0]):
            self._prims_tex.write(data.tobytes())
        else:
            if self._prims_tex is not None:
                self._prims_tex.release()
            prims_tex = self.ctx.texture((TEXELS_PER_PRIMITIVE, data.shape[0]), 4, data.tobytes(), dtype="f4")
            prims_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._prims_tex = prims_tex

    def _use_variant(self, meshes: bool) -> None:
        """Switch to the ray-cast programs with (or without) the mesh layer: a scene without meshes runs exactly
        the analytic programs it always ran; the mesh variant and the mesh pass are built on first use."""
        if meshes not in self._variants:
            prog = self.ctx.program(vertex_shader=VERTEX_SHADER,
                                    fragment_shader=fragment_shader(self.settings.antialiasing, self._two_pass,
                                                                    self.settings.adaptive_cull, meshes=True))
            edge_prog = edge_vao = None
            if self._two_pass:
                edge_prog = self.ctx.program(vertex_shader=VERTEX_SHADER, fragment_shader=edge_pass_shader(meshes=True))
                edge_vao = self.ctx.vertex_array(edge_prog, [])
            self._variants[meshes] = (prog, edge_prog, self.ctx.vertex_array(prog, []), edge_vao)
            from psyop.rendering.mesh_pass import MeshPass

            self._mesh_pass = MeshPass(self.ctx)
        self._prog, self._edge_prog, self._vao, self._edge_vao = self._variants[meshes]
        self._with_meshes = meshes
        self._uniform_values = {}  # the other programs hold other values: every scene uniform is written again
        self._set_constant_uniforms()
        if meshes:
            for prog in self._programs():
                _uniform(prog, "u_mesh_colour").value = 3
                _uniform(prog, "u_mesh_inv_distance").value = 4

    def _draw_meshes(self, state: _EyeState, camera: EyeCamera) -> None:
        """The mesh pass for this eye (before the ray-cast, which composites its target per ray sample)."""
        assert self._mesh_pass is not None
        if state.mesh_target is None:
            state.mesh_target = self._mesh_pass.target(state.width_px, state.height_px)
        self._mesh_pass.draw(state.mesh_target, camera, self.scene.meshes)
        state.mesh_target.colour.use(3)
        state.mesh_target.inv_distance.use(4)
        for prog in self._programs():
            _uniform(prog, "u_mesh_samples").value = self._mesh_pass.samples

    def _pack(self, p: Primitive, layer: int | None, sizes: list[tuple[int, int]]) -> list[float]:
        """One primitive's rows of the primitive table, flat (TEXELS_PER_PRIMITIVE x 4: axes and shape,
        material, border, edge effort), as Python numbers: a head-tracked frame packs every primitive."""
        m = p.material
        u, v = p.half_u_m, p.half_v_m
        row: list[float] = [u[0], u[1], u[2], 0.0 if p.shape is Shape.DISC else 1.0, v[0], v[1], v[2]]
        if isinstance(m, Solid):
            row += [0.0, *m.colour, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        elif isinstance(m, GridMaterial):
            row += [2.0, *m.background, 0.0, *m.line_colour, m.lines_per_side, 0.0, 0.0, 0.0, m.line_width_fraction]
        elif isinstance(m, Grating):
            window = {WindowKind.NONE: 0.0, WindowKind.GAUSSIAN: 1.0, WindowKind.RAISED_COSINE: 2.0}[m.window]
            phase = m.phase_cycles - math.floor(m.phase_cycles)  # float64 here: float32 keeps it exact to 6e-8 cycles
            row += [3.0, m.mean, m.amplitude, phase, 0.0 if m.waveform is Waveform.SINE else 1.0,
                    m.cycles_u, m.cycles_v, m.deg_per_unit_u, m.deg_per_unit_v, window, m.window_1, m.window_2, 0.0]
        else:
            assert layer is not None
            row += [1.0, 0.0, 0.0, 0.0, layer, 0.0, 0.0, 0.0, 0.0, sizes[layer][0], sizes[layer][1], m.repeats, 0.0]
        b = p.border
        row += [0.0, 0.0, 0.0, 0.0, 0.0, 0.0] if b is None else [1.0, b.amplitude, b.cycles, b.phase_rad, b.offset, b.side]
        row += [0 if p.edge_samples_per_axis is None else min(int(p.edge_samples_per_axis), self.settings.samples_per_axis),
                0.0]
        return row

    @property
    def scene(self) -> Scene:
        assert self._scene is not None
        return self._scene

    def _programs(self) -> list[moderngl.Program]:
        return [p for p in (self._prog, self._edge_prog) if p is not None]

    def _set_if_present(self, name: str, value: Any) -> None:  # Any: a GL uniform value
        if self._uniform_values.get(name) == value:  # a uniform is written when its value changes
            return
        self._uniform_values[name] = value
        for prog in self._programs():
            if name in self._members(prog):
                _uniform(prog, name).value = value

    def _members(self, prog: moderngl.Program) -> moderngl.Program | frozenset[str]:  # Program: benchmarks/former.py
        """The names a program declares (``name in prog`` walks them all: looked up once per program)."""
        names = self._member_names.get(id(prog))
        if names is None:
            names = self._member_names[id(prog)] = frozenset(prog)
        return names

    # -- per-eye targets ------------------------------------------------------------------------
    def _eye_state(self, eye: str, width_px: int, height_px: int) -> _EyeState:
        state = self._eyes.get(eye)
        if state is not None and (state.width_px, state.height_px) == (width_px, height_px):
            return state
        if state is not None:
            self._release_eye(state)
        colour = self.ctx.texture((width_px, height_px), 4, dtype="f4")
        depth = self.ctx.depth_renderbuffer((width_px, height_px)) if self._two_pass else None
        fbo = self.ctx.framebuffer(color_attachments=[colour], depth_attachment=depth)
        msaa = None
        if self.settings.antialiasing is AntiAliasing.MSAA:
            samples = min(int(self.settings.msaa_samples), int(self.ctx.max_samples))
            rb = self.ctx.renderbuffer((width_px, height_px), 4, samples=samples, dtype="f4")
            msaa = self.ctx.framebuffer(color_attachments=[rb])
        state = _EyeState(width_px, height_px, fbo, colour, msaa, None, depth)
        self._eyes[eye] = state
        return state

    def _release_eye_aperture(self, state: _EyeState) -> None:
        if state.aperture is not None:
            state.aperture.release()

    def _release_eye(self, state: _EyeState) -> None:
        self._release_eye_aperture(state)
        self._release_linear(state)
        if state.mesh_target is not None:
            state.mesh_target.release()
        for obj in (state.fbo, state.colour, state.msaa_fbo, state.depth):
            if obj is not None:
                obj.release()

    def _aperture_mask(self, camera: EyeCamera) -> np.ndarray:
        """Screen-fixed aperture coverage per pixel (rows bottom-up, as OpenGL stores them).

        Computed once per eye from the first valid camera's pixel rays: for an image at
        infinity those directions do not depend on the centre of projection, so the aperture
        ignores ocular parallax exactly; edges are box-filtered over one pixel's angle.
        """
        w, h = camera.width_px, camera.height_px
        ap = self.scene.aperture
        if ap is None:
            return np.ones((h, w), dtype=np.float32)
        ys, xs = np.mgrid[0:h, 0:w]
        xy = np.stack([xs.ravel() + 0.5, ys.ravel() + 0.5], axis=-1)
        d = pixel_rays(camera, xy)
        dx = pixel_rays(camera, xy + [1.0, 0.0])
        axis = np.array([math.tan(math.radians(ap.azimuth_deg)), math.tan(math.radians(ap.elevation_deg)), -1.0])
        axis /= np.linalg.norm(axis)
        theta = np.arccos(np.clip(d @ axis, -1.0, 1.0))
        pix = np.arccos(np.clip(np.sum(d * dx, axis=-1), -1.0, 1.0))
        cov = np.clip(0.5 + (math.radians(ap.radius_deg) - theta) / np.maximum(pix, 1e-12), 0.0, 1.0)
        return cov.reshape(h, w)[::-1].astype(np.float32)

    # -- rendering ------------------------------------------------------------------------------
    def render(self, camera: EyeCamera) -> FrameResult:
        """Render (or reuse) the frame for ``camera``'s eye."""
        eye = _eye_key(camera)
        self.stats.frames_requested += 1
        usable = camera_is_usable(camera)
        try:
            size = (int(camera.width_px), int(camera.height_px))
        except (TypeError, ValueError, AttributeError, OverflowError):
            size = (0, 0)
        if not (size[0] > 0 and size[1] > 0):
            if eye not in self._eyes:
                raise ValueError("a camera without a valid image size before any valid camera for this eye")
            size = (self._eyes[eye].width_px, self._eyes[eye].height_px)
            usable = False
        state = self._eye_state(eye, *size)
        if usable:
            state.last_valid_camera = camera
        else:
            self.stats.invalid_cameras += 1
        use = state.last_valid_camera
        decision = None
        same_scene = state.rendered_scene is self._scene or state.rendered_scene == self._scene
        if use is not None and self.settings.reuse_tolerance_px is not None and same_scene:
            decision = decide_reuse(state.last_rendered_camera, use, lambda: self._depth_range_m(state),
                                    self.settings.reuse_tolerance_px)
            if decision.skip:
                self.stats.frames_skipped += 1
                self.stats.largest_skipped_bound_px = max(self.stats.largest_skipped_bound_px, decision.bound_px)
                return FrameResult(eye, False, usable, state.last_rendered_camera, decision)
        self._draw(state, use)
        self.stats.frames_rendered += 1
        return FrameResult(eye, True, usable, use, decision)

    @staticmethod
    def _depth_range_m(state: _EyeState) -> tuple[float, float]:
        """The depth range of the eye's last image's scene from its centre of projection (computed on first use)."""
        if state.depth_range_m is None:
            assert state.rendered_scene is not None and state.depth_centre_m is not None
            state.depth_range_m = state.rendered_scene.depth_range_m(state.depth_centre_m)
        return state.depth_range_m

    def _draw(self, state: _EyeState, camera: EyeCamera | None) -> None:
        """Draw the eye's image from ``camera`` (None: no valid camera yet, the background)."""
        if state.aperture is None and camera is not None:
            mask = self._aperture_mask(camera)
            state.aperture = self.ctx.texture((state.width_px, state.height_px), 1, mask.tobytes(), dtype="f4")
            state.aperture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        if camera is not None and self.scene.meshes:
            self._draw_meshes(state, camera)
        resolved = state.fbo if self._output is None else self._linear_target(state)
        target = state.msaa_fbo if state.msaa_fbo is not None else resolved
        target.use()
        self.ctx.viewport = (0, 0, state.width_px, state.height_px)
        if camera is None:
            bg = self.scene.background
            target.clear(bg[0], bg[1], bg[2], 1.0)
            state.last_rendered_camera = None
            state.rendered_scene = None
        else:
            cop = np.asarray(camera.centre_of_projection_m, dtype=np.float64)
            rel_m = self._centres_head - self._centre_w[:, None] * cop  # directions stay put
            rel = np.zeros((MAX_PRIMITIVES, 4), dtype=np.float32)
            rel[: len(self._centres_head), :3] = rel_m
            rel[: len(self._centres_head), 3] = self._centre_w
            self._centres.write(rel.tobytes())
            self._centres.bind_to_uniform_block(0)
            near, far = near_far_m(camera)
            far = max(far, self._scene_far_m + float(np.linalg.norm(cop)))  # never clip a scene primitive
            ray = np.asarray(camera.pixel_to_ray, dtype=np.float32).T.tobytes()
            for prog in self._programs():
                _uniform(prog, "u_ray").write(ray)
                _uniform(prog, "u_size_px").value = (float(state.width_px), float(state.height_px))
                _uniform(prog, "u_near_m").value = near
                _uniform(prog, "u_far_m").value = min(far, 3.0e38)
            assert self._prims_tex is not None and self._layers_tex is not None  # set_scene uploaded both
            assert state.aperture is not None  # made above from the first camera
            self._prims_tex.use(0)
            self._layers_tex.use(1)
            state.aperture.use(2)
            if self._two_pass:
                self._draw_two_pass(state, camera, rel_m)
            else:
                self._vao.render(moderngl.TRIANGLES, vertices=3)
            state.last_rendered_camera = camera
            state.rendered_scene = self._scene
            self._keep_depth_centre(state, cop)
        if state.msaa_fbo is not None:
            self.ctx.copy_framebuffer(resolved, state.msaa_fbo)
        if self._output is not None:
            self._final_pass(state)

    def _keep_depth_centre(self, state: _EyeState, cop: np.ndarray) -> None:
        """After a draw: the reuse bounds wait until a frame may reuse this image (:meth:`_depth_range_m`)."""
        state.depth_range_m, state.depth_centre_m = None, cop

    def _screen_bounds_px(self, rel_m: np.ndarray, camera: EyeCamera, state: _EyeState) -> np.ndarray:
        """Each primitive's conservative screen box for the two-pass cull (psyop.rendering.screen_bounds)."""
        return screen_bounds_px(rel_m, self._half_axes_m[0], self._half_axes_m[1], camera.pixel_to_ray,
                                state.width_px, state.height_px)

    def _draw_two_pass(self, state: _EyeState, camera: EyeCamera, rel_m: np.ndarray) -> None:
        """Adaptive sampling in two passes: one ray everywhere (edge pixels get depth 0), then
        the SxS grid only where the depth test (GREATER than 0) lets a fragment through."""
        bounds = np.zeros((MAX_PRIMITIVES, 4), dtype=np.float32)
        assert self._bounds is not None and self._edge_vao is not None  # built with the two-pass programs
        bounds[: len(rel_m)] = self._screen_bounds_px(rel_m, camera, state)
        self._bounds.write(bounds.tobytes())
        self._bounds.bind_to_uniform_block(1)
        self.ctx.enable(moderngl.DEPTH_TEST)
        try:
            self.ctx.depth_func = "1"  # always: the first pass writes every pixel's edge mark
            self._vao.render(moderngl.TRIANGLES, vertices=3)
            self.ctx.depth_func = ">"  # the full-screen triangle sits at depth 0.5
            self._edge_vao.render(moderngl.TRIANGLES, vertices=3)
        finally:
            self.ctx.depth_func = "<"
            self.ctx.disable(moderngl.DEPTH_TEST)

    # -- results --------------------------------------------------------------------------------
    def finish(self) -> None:
        """Wait for the GPU (for timing)."""
        self.ctx.finish()

    def framebuffer(self, eye: str) -> moderngl.Framebuffer:
        """The eye's resolved framebuffer (for presenting in a window)."""
        return self._eyes[eye].fbo

    def copy_to(self, eye: str, framebuffer: moderngl.Framebuffer) -> None:
        """Copy the eye's last frame into another framebuffer of the same size (a display's image,
        e.g. an OpenXR swapchain image): a blit that converts the float image to the target's
        format (8-bit unsigned normalised for RGBA8: values pass unchanged, no sRGB encoding)."""
        state = self._eyes[eye]
        if tuple(framebuffer.size) != (state.width_px, state.height_px):
            raise ValueError(f"target {framebuffer.size} differs from the {eye} eye's image "
                             f"{(state.width_px, state.height_px)}")
        self.ctx.copy_framebuffer(framebuffer, state.fbo)

    def colour_texture(self, eye: str) -> moderngl.Texture:
        """The eye's resolved float colour texture (for a GPU-side check: psyop.rendering.frame_check)."""
        return self._eyes[eye].colour

    def image(self, eye: str = "right") -> np.ndarray:
        """(H, W, 3) float32 image of the eye's last frame, top row first, values in [0, 1]."""
        state = self._eyes[eye]
        raw = state.fbo.read(components=4, dtype="f4")
        img = np.frombuffer(raw, dtype=np.float32).reshape(state.height_px, state.width_px, 4)
        return np.ascontiguousarray(img[::-1, :, :3])

    def edge_mask(self, eye: str = "right") -> np.ndarray:
        """(H, W) bool, top row first: the pixels of the eye's last frame that took the adaptive
        edge path (SxS samples)."""
        state = self._eyes[eye]
        raw = state.fbo.read(components=4, dtype="f4")
        alpha = np.frombuffer(raw, dtype=np.float32).reshape(state.height_px, state.width_px, 4)[..., 3]
        return np.ascontiguousarray(alpha[::-1] < 0.75)

    def edge_pixel_count(self, eye: str = "right") -> int:
        """How many pixels of the eye's last frame took the adaptive edge path (32x32 samples)."""
        return int(np.count_nonzero(self.edge_mask(eye)))

    def edge_block_count(self, eye: str = "right", block_px: int = 4) -> int:
        """How many aligned ``block_px`` squares (window coordinates, origin bottom-left) hold at
        least one edge pixel: the work unit of a SIMD rasteriser (llvmpipe shades 4x4 blocks; GPU
        warps are similar), which pays for a block's samples when any of its pixels needs them."""
        mask = self.edge_mask(eye)[::-1]
        h, w = mask.shape
        padded = np.zeros((-(-h // block_px) * block_px, -(-w // block_px) * block_px), dtype=bool)
        padded[:h, :w] = mask
        blocks = padded.reshape(padded.shape[0] // block_px, block_px, padded.shape[1] // block_px, block_px)
        return int(np.count_nonzero(blocks.any(axis=(1, 3))))

    def linear_image(self, eye: str = "right") -> np.ndarray:
        """(H, W, 3) float32, top row first: the eye's last ray-cast values before the final pass (normalised
        luminance on a calibrated display; the same as :meth:`image` without one)."""
        state = self._eyes[eye]
        if state.linear_fbo is None:
            return self.image(eye)
        raw = state.linear_fbo.read(components=4, dtype="f4")
        img = np.frombuffer(raw, dtype=np.float32).reshape(state.height_px, state.width_px, 4)
        return np.ascontiguousarray(img[::-1, :, :3])

    def image_uint8(self, eye: str = "right") -> np.ndarray:
        """(H, W, 3) uint8 image (rounded) of the eye's last frame."""
        return np.round(np.clip(self.image(eye), 0.0, 1.0) * 255.0).astype(np.uint8)

    # -- lifetime -------------------------------------------------------------------------------
    def release(self) -> None:
        """Free every GPU object (and the context if this renderer created it)."""
        for state in self._eyes.values():
            self._release_eye(state)
        self._eyes.clear()
        for obj in (self._prims_tex, self._layers_tex, self._centres, self._bounds, self._table_tex,
                    self._output_vao, self._output_prog,
                    *(o for variant in self._variants.values() for o in variant)):
            if obj is not None:
                obj.release()
        if self._mesh_pass is not None:
            self._mesh_pass.release()
        self._prims_tex = self._layers_tex = None
        if self._owns_ctx:
            self.ctx.release()

    def __enter__(self) -> Renderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()
