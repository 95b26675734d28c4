"""``psyop audit`` on mesh items (psyop.audit.meshes): each mesh's rendered silhouette (its visible area in a
mask render of the frame, the mesh pass's MSAA 4x) against exact ray-triangle intersection
(psyop.rendering.mesh_exact, numpy), occlusion between meshes and primitives included. The teaser passes with
its mesh rows, a mixed mesh/primitive scene passes, and the reference computed from a mesh moved by a known
offset fails."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from psyop.audit import AuditSettings, format_table, run_audit
from psyop.audit.masks import FrameMeasurer
from psyop.audit.meshes import MESH_AREA_RELATIVE_TOLERANCE
from psyop.audit.run import FrameRecord, _check, mesh_findings
from psyop.protocol.loader import load_protocol
from psyop.rendering import RenderSettings, Scene, Solid
from psyop.rendering.measure import RIGHT_CENTRE_M, right_eye_camera
from psyop.rendering.mesh_scene import MeshInstance, model_matrix
from psyop.rendering.renderer import create_headless_context
from psyop.rendering.scene import Primitive, Shape
from tests.rendering.mesh_helpers import asset, disc_part, quad_part

TEASER = Path(__file__).resolve().parents[1] / "protocols" / "examples" / "teaser.yaml"


@pytest.fixture(scope="module")
def ctx():
    context = create_headless_context()
    yield context
    context.release()


@pytest.fixture(scope="module")
def measurer(ctx):
    m = FrameMeasurer(ctx, RenderSettings(samples_per_axis=8, reuse_tolerance_px=None))
    yield m
    m.release()


def test_teaser_audit_passes_with_mesh_rows(ctx):
    report = run_audit(load_protocol(TEASER), AuditSettings(gazes=1), ctx=ctx, base_dir=TEASER.parent)
    assert report.passed, "\n".join(report.failures)
    checks = [(rec.frame.mode, c) for rec in report.records for c in rec.meshes]
    # both meshes compared in every frame of both modes (the candle's BLEND flame hides nothing: left out)
    assert {(mode, c.name) for mode, c in checks} == {(m, n) for m in ("ocular", "conventional")
                                                       for n in ("bottle", "candle")}
    assert all(not c.skipped and c.exact_px2 > 1000 for _, c in checks)
    assert max(c.relative_error for _, c in checks) < MESH_AREA_RELATIVE_TOLERANCE
    # the candle hides part of the bottle, and ocular parallax reveals more of it at this gaze (exact)
    bottle = {rec.frame.interval: c.exact_px2 for rec in report.records for c in rec.meshes if c.name == "bottle"}
    assert len(bottle) == 2
    table = format_table(report)
    assert "mesh silhouettes" in table and "\nbottle " in table and "\ncandle " in table
    assert "not yet compare" not in table


def _mixed_scene(offset_m: float = 0.0) -> Scene:
    """A mesh quad at 1 m, a farther analytic disc it partly covers, a nearer analytic rect over its corner,
    and a mesh disc behind the quad; ``offset_m`` moves the mesh quad right."""
    centre = RIGHT_CENTRE_M + np.array([0.0, 0.0, -1.0])
    quad = MeshInstance(asset(quad_part(0.03, 0.03, colour=(0.0, 1.0, 0.0, 1.0))),
                        tuple(model_matrix(centre + [offset_m, 0.0, 0.0], (0, 0, 0), 1.0).reshape(-1)), "quad")
    back = MeshInstance(asset(disc_part(0.05, 128, colour=(1.0, 1.0, 0.0, 1.0))),
                        tuple(model_matrix(centre + [-0.04, 0.01, -0.5], (20, 0, 0), 1.0).reshape(-1)), "back")
    far = Primitive(Shape.DISC, tuple(centre + [0.03, 0.0, -1.0]), (0.06, 0, 0), (0, 0.06, 0), Solid((1, 0, 0)),
                    name="far_disc")
    near = Primitive(Shape.RECT, tuple(centre + [-0.012, 0.01, 0.5]), (0.006, 0, 0), (0, 0.004, 0),
                     Solid((0, 0, 1)), name="near_rect")
    return Scene((far, near), background=(0.5, 0.5, 0.5), meshes=(quad, back))


@pytest.mark.parametrize("mode", ["conventional", "ocular", "reversed"])
def test_mixed_mesh_and_primitive_scene_passes(measurer, mode):
    cam = dataclasses.replace(right_eye_camera(8.0, 4.0, mode), width_px=180, height_px=200)
    scene = _mixed_scene()
    checks = {c.name: c for c in measurer.mesh_checks(scene, cam)}
    assert set(checks) == {"quad", "back"}
    for c in checks.values():
        assert not c.skipped and c.exact_px2 > 5 and c.passed, c
        assert c.relative_error < MESH_AREA_RELATIVE_TOLERANCE
    # occlusion counted: the quad hides part of the back disc, the near rect part of the quad
    alone = {c.name: c for c in measurer.mesh_checks(dataclasses.replace(scene, primitives=()), cam)}
    assert checks["quad"].exact_px2 < alone["quad"].exact_px2
    assert checks["quad"].rendered_px2 < alone["quad"].rendered_px2
    # the primitives' visible areas see the meshes in front of them (the mask scenes draw them, black)
    areas = measurer.visible_areas_px(scene, cam)
    bare = measurer.visible_areas_px(dataclasses.replace(scene, meshes=()), cam)
    assert areas[0] < bare[0] - 1.0


def test_reference_from_a_moved_mesh_fails(measurer):
    """The exact reference of the quad moved 3 mm right (about a pixel at this scale): the audit flags it."""
    cam = dataclasses.replace(right_eye_camera(8.0, 4.0, "ocular"), width_px=180, height_px=200)
    scene = _mixed_scene()
    checks = {c.name: c for c in measurer.mesh_checks(scene, cam, exact_scene=_mixed_scene(0.003))}
    quad = checks["quad"]
    assert not quad.passed, quad
    # a sideways shift keeps the area nearly equal: the per-pixel mismatch is what catches it
    assert quad.error_px2 <= quad.tolerance_px2 and quad.mismatch_px2 > quad.mismatch_tolerance_px2, quad
    record = _record(tuple(checks.values()))
    failures, _ = mesh_findings([record])
    assert any(f.startswith("FAIL mesh quad: rendered silhouette") for f in failures), failures
    # and the audit's report fails with it (psyop audit exits 1 on any failure line)
    report_failures, _ = _check([record], ["quad", "back"], 0.0)
    assert any(f.startswith("FAIL mesh quad") for f in report_failures)


def _record(meshes) -> FrameRecord:
    from psyop.audit.frames import AuditFrame

    frame = AuditFrame("c", 1, {}, "interval1", 0, 1, "ocular", "right", 0, 0.0)
    return FrameRecord(frame, (), (), (), {}, np.zeros((1, 1, 3)), meshes=meshes)
