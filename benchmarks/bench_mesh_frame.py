"""Mesh frame cost (issue 26): a frame with a mesh disc of 1k, 10k, 100k and 1M triangles as a ratio to the
same frame with the analytic disc of the same geometry (the fan's vertices lie on the analytic disc's rim:
its area is the disc's times (n / 2 pi) sin(2 pi / n): 0.0007 % less at 1k triangles), right eye, ocular mode, frames interleaved (mesh,
analytic, mesh, ...), median of the per-pair ratios; and the slope: the mesh frame's median ms and the
ratio, each fitted by least squares against the triangle count over the rows, per 100k triangles. And the
CPU side of an egocentric frame with the dining-room mesh against the same frame with the former box room
(bench_frame_cpu's frame, its 'after' path, the two rooms interleaved), with the part of the difference that is
llvmpipe's GPU work on the frame thread (:class:`_Timed`) split from the rest. The room rows alone:
``PYTHONPATH=$PWD python -m benchmarks.bench_mesh_frame --rooms``.

Not measured here: stereo mesh-disc frames, and a GPU (none here: the 90 Hz budget a GPU must show is in
docs/rendering.md). On llvmpipe
the frame times are CPU times of the software rasteriser: ratios only, absolute times are context.
``quick``: a 160 x 160 window around the disc and 3 frame pairs.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np

from psyop.mesh.asset import AlphaMode, MeshAsset, MeshPart
from psyop.rendering.camera_math import crop_camera, project_points_px
from psyop.rendering.measure import RIGHT_CENTRE_M, right_eye_camera
from psyop.rendering.mesh_scene import MeshInstance, model_matrix
from psyop.rendering.renderer import Renderer, RenderSettings, create_headless_context
from psyop.rendering.scene import Primitive, Scene, Shape, Solid

TRIANGLES = (1_000, 10_000, 100_000, 1_000_000)
#: protocols/egocentric.yaml's former analytic room (kind: room), the same size as the dining-room mesh
BOX_ROOM = """  - id: room
    kind: room
    width_m: 4
    depth_m: 5
    height_m: 2.6
    table_height_m: 0.75
    eye_height_m: 1.2
"""
RADIUS_M = 0.05
CENTRE_M = RIGHT_CENTRE_M + np.array([0.0, 0.0, -1.0])


def _disc_asset(segments: int) -> MeshAsset:
    a = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    pos = np.concatenate([[(0.0, 0.0, 0.0)], np.stack([RADIUS_M * np.cos(a), RADIUS_M * np.sin(a), 0 * a], axis=-1)])
    i = np.arange(segments, dtype=np.uint32)
    idx = np.stack([np.zeros(segments, dtype=np.uint32), 1 + i, 1 + (i + 1) % segments], axis=-1)
    part = MeshPart(node="disc", mesh_index=0, primitive_index=0, positions=pos, indices=idx, normals=None,
                    texcoords=None, colours=None, base_colour=(1.0, 0.0, 0.0, 1.0), texture=None,
                    alpha_mode=AlphaMode.OPAQUE, alpha_cutoff=0.5, double_sided=True,
                    bbox_min=pos.min(axis=0), bbox_max=pos.max(axis=0))
    return MeshAsset(path=Path(f"disc{segments}.glb"), sha256="0" * 64, node=None, parts=(part,),
                     bbox_min=part.bbox_min, bbox_max=part.bbox_max)


def _time_frame(renderer: Renderer, camera) -> float:  # type: ignore[no-untyped-def]
    start = time.perf_counter()
    renderer.render(camera)
    renderer.image()  # waits for the frame
    return time.perf_counter() - start


class _Timed:
    """A GL object whose ``method`` calls add their thread time to ``totals['gpu_s']`` (and, for a draw, its
    triangles to ``totals['triangles']``); everything else passes through. On llvmpipe a mesh batch's draw call
    runs the software GPU's geometry stage (vertex shading, clipping, triangle setup and binning) and the
    clear of the multisampled mesh target fills its samples, both on the calling thread: work a GPU does itself."""

    def __init__(self, obj, method: str, totals: dict[str, float]) -> None:  # type: ignore[no-untyped-def]
        self._obj, self._method, self._totals = obj, method, totals

    def __getattr__(self, name: str):  # type: ignore[no-untyped-def]
        real = getattr(self._obj, name)
        if name != self._method:
            return real

        def timed(*args, **kwargs):  # type: ignore[no-untyped-def]
            start = time.thread_time()
            real(*args, **kwargs)
            self._totals["gpu_s"] += time.thread_time() - start
            self._totals["triangles"] += kwargs.get("vertices", 0) / 3

        return timed


def _time_gpu_work(variant) -> dict[str, float]:  # type: ignore[no-untyped-def]
    """Wrap the variant's uploaded mesh batches (their draws) and mesh targets (their clears) in :class:`_Timed`;
    the totals they add to."""
    totals = {"gpu_s": 0.0, "triangles": 0.0}
    renderer = variant.renderer._renderer
    if renderer._mesh_pass is not None:
        for _, gpu in renderer._mesh_pass.meshes.values():
            for batch in gpu.batches:
                batch.vao = _Timed(batch.vao, "render", totals)
        for state in renderer._eyes.values():
            if state.mesh_target is not None:
                state.mesh_target.fbo = _Timed(state.mesh_target.fbo, "clear", totals)
    return totals


def _room_cpu(texts: dict[str, str], ctx, scale: float, frames: int, block: int) -> dict[str, dict[str, float]]:  # type: ignore[no-untyped-def]
    """Per room: median CPU (thread) ms per frame, bench_frame_cpu's frame (its 'after' path, ``_frame``), the
    rooms interleaved in blocks; and the mean thread ms per frame of llvmpipe's GPU work (:class:`_Timed`) and
    the triangles drawn per frame."""
    import tempfile

    from benchmarks.bench_frame_cpu import _frame, _setup
    from psyop.protocol import load_protocol

    variants, totals, times = {}, {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        try:
            for name, text in texts.items():
                path = Path(tmp) / f"{name}.yaml"
                path.write_text(text)
                variants[name] = _setup(load_protocol(path), ctx, scale, False, 1)
                for _ in range(4):  # warm-up: programs, uploads, the aperture mask, the first check
                    _frame(*variants[name])
                totals[name], times[name] = _time_gpu_work(variants[name][0]), []
            for rep in range(max(1, frames // block)):
                for name in (list(texts) if rep % 2 == 0 else list(texts)[::-1]):
                    times[name] += [_frame(*variants[name]) for _ in range(block)]
        finally:
            for v in variants.values():
                v[0].renderer.close()
    return {name: {"ms": statistics.median(times[name]), "gpu_ms": 1e3 * totals[name]["gpu_s"] / len(times[name]),
                   "triangles": totals[name]["triangles"] / len(times[name]), "frames": len(times[name]),
                   "eyes": len(variants[name][0].renderer.eyes)} for name in texts}


def _room_rows(ctx, quick: bool) -> list[str]:  # type: ignore[no-untyped-def]
    """CPU ms per stereo frame of the egocentric protocol with the dining-room mesh and with the box room, and
    how much of the difference is llvmpipe's GPU work on the calling thread (:class:`_Timed`)."""
    import re

    from benchmarks.bench_frame_cpu import protocol_text

    mesh_text = protocol_text("egocentric", False)
    box_text, n = re.subn(r"(?ms)^  - id: room\n    kind: mesh\n.*?(?=^  - id: pencil)", BOX_ROOM, mesh_text)
    assert n == 1, "protocols/egocentric.yaml: no mesh room item to swap"
    frames, block = (8, 4) if quick else (160, 8)
    r = _room_cpu({"box": box_text, "mesh": mesh_text}, ctx, 0.05 if quick else 0.1, frames, block)
    box, mesh = r["box"], r["mesh"]
    extra = mesh["ms"] - box["ms"]
    return ["", (f"CPU (thread) ms per frame, egocentric ({mesh['eyes']} eyes, median of {mesh['frames']} frames each, "
                 f"the two rooms interleaved in blocks of {block}; bench_frame_cpu's frame, its 'after' path; the reach "
                 "target as the protocol has it). 'llvmpipe GPU work': the thread time (mean per frame) inside the "
                 "mesh batches' draw calls (on llvmpipe the software GPU's geometry stage, vertex shading, clipping, "
                 "triangle setup and binning, per triangle drawn) and the mesh targets' clears (filling their "
                 "samples), run on the calling thread: work a GPU does itself. 'The rest': the difference less that "
                 "(Python, GL state, uniforms, the mesh-layer ray-cast's setup): what the goal 'under 1 ms more, no "
                 "per-frame Python work per node or per triangle' is about on a GPU."), "",
            "| room | CPU ms per frame | minus the box room, ms | of it llvmpipe GPU work, ms | the rest, ms | "
            "triangles drawn per frame |", "|---|---|---|---|---|---|",
            f"| box room (kind: room) | {box['ms']:.2f} | 0 | {box['gpu_ms']:.2f} | 0 | {box['triangles']:.0f} |",
            f"| dining room (assets/dining_room.glb) | {mesh['ms']:.2f} | {extra:+.2f} | {mesh['gpu_ms']:.2f} | "
            f"{extra - mesh['gpu_ms'] + box['gpu_ms']:+.2f} | {mesh['triangles']:.0f} |"]


def slope_per_100k(triangles: list[int], values: list[float]) -> tuple[float, float]:
    """(slope per 100k triangles, intercept) of the least-squares line through (triangles, values)."""
    slope, intercept = np.polyfit(np.asarray(triangles, dtype=np.float64), np.asarray(values, dtype=np.float64), 1)
    return float(slope) * 1e5, float(intercept)


def _slope_lines(fit: list[tuple[int, float, float]]) -> list[str]:
    counts = [n for n, _, _ in fit]
    ms, ms0 = slope_per_100k(counts, [t for _, t, _ in fit])
    ratio, ratio0 = slope_per_100k(counts, [r for _, _, r in fit])
    return ["", (f"Slope, least squares over the {len(fit)} rows ({', '.join(f'{n:,}' for n in counts)} triangles): "
                 f"{ms:.3f} ms per 100k triangles (intercept {ms0:.2f} ms), ratio {ratio:.3f} per 100k triangles "
                 f"(intercept {ratio0:.2f}).")]


def run(out: Path, quick: bool = False) -> str:
    pairs = 3 if quick else 15
    ctx = create_headless_context()
    camera = right_eye_camera(5.0, 0.0, "ocular")
    if quick:
        x, y = project_points_px(camera, [CENTRE_M])[0]
        camera = crop_camera(camera, int(x) - 80, int(y) - 80, 160, 160)
    analytic = Scene((Primitive(Shape.DISC, tuple(CENTRE_M), (RADIUS_M, 0, 0), (0, RADIUS_M, 0), Solid((1, 0, 0)),
                                name="disc"),), background=(0, 0, 0))
    settings = RenderSettings(reuse_tolerance_px=None)
    lines = ["## Mesh frame cost (benchmarks/bench_mesh_frame.py)", "",
             (f"Right eye, ocular, {camera.width_px} x {camera.height_px} px, a disc {2 * RADIUS_M:g} m across at 1 m; "
              f"{pairs} interleaved frame pairs, median of per-pair ratios (first frame of each discarded)."), "",
             "| triangles | mesh frame ms (median) | analytic frame ms | ratio mesh / analytic |", "|---|---|---|---|"]
    fit: list[tuple[int, float, float]] = []  # (triangles, mesh ms, ratio) per row
    try:
        with Renderer(analytic, settings, ctx=ctx) as flat:
            _time_frame(flat, camera)
            for n in TRIANGLES:
                model = tuple(model_matrix(CENTRE_M, (0, 0, 0), 1.0).reshape(-1))
                scene = Scene((), background=(0, 0, 0), meshes=(MeshInstance(_disc_asset(n), model, "disc"),))
                with Renderer(scene, settings, ctx=ctx) as mesh:
                    _time_frame(mesh, camera)
                    m, a = [], []
                    for _ in range(pairs):
                        m.append(_time_frame(mesh, camera))
                        a.append(_time_frame(flat, camera))
                ratio = statistics.median(x / y for x, y in zip(m, a))
                fit.append((n, 1e3 * statistics.median(m), ratio))
                lines.append(f"| {n} | {1e3 * statistics.median(m):.2f} | {1e3 * statistics.median(a):.2f} | "
                             f"{ratio:.2f} |")
        lines += _slope_lines(fit)
        lines += _room_rows(ctx, quick)
    finally:
        ctx.release()
    lines += ["", ("Not measured: stereo mesh-disc frames, and any GPU (none here; the 90 Hz budget a GPU must show: "
                   "docs/rendering.md). llvmpipe: ratios only, absolute times are context.")]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    import sys

    if "--rooms" in sys.argv[1:]:  # the room rows alone (full size: 160 frames per room)
        context = create_headless_context()
        try:
            print("\n".join(_room_rows(context, "--quick" in sys.argv[1:])))
        finally:
            context.release()
    else:
        print(run(Path("bench"), quick="--quick" in sys.argv[1:]))
