"""The mesh pass's per-frame CPU cuts (issue 26 item 6: uniforms looked up once and written when they change,
each instance's model matrix and bounding sphere once for both eyes, the frustum test in two reductions, the
visible runs found with numpy, the normal matrix only for lambert shading) draw the same images: session
frames of the egocentric study in the mesh dining room and of the teaser example, both eyes, a moving head
(turned far enough that parts leave the frustum), every pixel equal to the former pass
(tests/rendering/former_mesh_pass.py); and a lambert-shaded mesh likewise. Timing: benchmarks/bench_mesh_frame.py."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from benchmarks.bench_frame_cpu import protocol_text
from psyop.protocol import load_protocol
from psyop.rendering import mesh_pass
from psyop.schedule import compile_schedule
from psyop.session.phases import mode_for
from psyop.session.plan import compile_plan
from psyop.session.scene_renderer import WATCHED_CHECK_EVERY, SceneRenderer
from tests.rendering.former_mesh_pass import FormerMeshPass

pytestmark = pytest.mark.cross_cpu  # mesh pass against the former pass, every pixel

REPO = Path(__file__).resolve().parents[2]


def _yaw(deg: float) -> tuple[float, float, float, float]:
    half = math.radians(deg) / 2.0
    return (math.cos(half), 0.0, math.sin(half), 0.0)


#: head poses: straight ahead, moved a little, turned 60 deg (the table leaves the view: culled parts), looking down
HEADS = (((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)), ((0.01, -0.02, 0.005), _yaw(5.0)),
         ((0.0, 0.0, 0.0), _yaw(60.0)), ((0.0, 0.1, 0.0), (math.cos(-0.35), math.sin(-0.35), 0.0, 0.0)))


def _images(text: str, tmp_path: Path, former: bool, ctx, monkeypatch: pytest.MonkeyPatch) -> list[np.ndarray]:
    path = tmp_path / "study.yaml"
    path.write_text(text)
    protocol = load_protocol(path)
    plan = compile_plan(protocol, tracker_ipd_m=0.064)
    rows = compile_schedule(protocol, 3).to_dict("records")[:2]
    phase = next(p for p in plan.phases if p.show == "stimulus")
    with monkeypatch.context() as m:
        if former:
            m.setattr(mesh_pass, "MeshPass", FormerMeshPass)
        r = SceneRenderer(plan, scale=0.12, ctx=ctx, owns_ctx=False, check_every=WATCHED_CHECK_EVERY)
        r.settings = dataclasses.replace(r.settings, samples_per_axis=8)  # the same for both, affordable on llvmpipe
        images = []
        try:
            for row in rows:
                for k, head in enumerate(HEADS):
                    fixation = (0.05 * math.sin(k), 0.02 * k, -1.0)
                    r.render(row, phase, mode_for(phase, row), k / 90.0, fixation, head_pose=head)
                    assert r._renderer is not None
                    assert isinstance(r._renderer._mesh_pass, FormerMeshPass) == former
                    images += [r._renderer.image(eye) for eye in plan.rig.eyes]
        finally:
            r.close()
    return images


@pytest.mark.parametrize("name", ["egocentric", "teaser", "egocentric-lambert"])
def test_the_mesh_pass_draws_the_same_frames_as_before(tmp_path: Path, gl_context, monkeypatch, name: str) -> None:
    if name == "teaser":
        text = (REPO / "protocols" / "examples" / "teaser.yaml").read_text()
        text = text.replace("file: ../../assets/", f"file: {(REPO / 'assets').resolve()}/")
    else:
        text = protocol_text("egocentric", False)
    if name == "egocentric-lambert":
        text = text.replace("    kind: mesh\n", "    kind: mesh\n    shading: lambert\n"
                            "    light: {direction: [0.3, 1.0, 0.5], ambient: 0.4}\n", 1)
    assert "kind: mesh" in text
    new = _images(text, tmp_path, False, gl_context, monkeypatch)
    old = _images(text, tmp_path, True, gl_context, monkeypatch)
    assert len(new) == len(old) > 0
    for k, (a, b) in enumerate(zip(new, old, strict=True)):
        assert np.array_equal(a, b), k
