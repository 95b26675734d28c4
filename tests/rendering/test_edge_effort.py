"""Anti-aliasing effort per primitive (issue 13: the egocentric room spent a 32x32 grid on plain
room-corner edges). Straight background edges take a few samples, stimulus edges the full grid;
the error of each choice is measured against exact polygon coverage."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest

from psyop.optics import VIVE_PRO, make_eye_camera
from psyop.protocol import parse_protocol
from psyop.rendering import Renderer, RenderSettings
from psyop.rendering.builders import ROOM_EDGE_SAMPLES_PER_AXIS
from psyop.rendering.camera_math import crop_camera, project_points_px
from psyop.rendering.measure import straight_edge_errors
from psyop.rendering.renderer import create_headless_context
from psyop.rendering.scene import Primitive, Shape, Solid
from psyop.schedule import compile_schedule
from psyop.stimulus import build_scene

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "tests"))
from protocol_texts import EGOCENTRIC_BOX_ROOM, EGOCENTRIC_MESH_PENCIL, EGOCENTRIC_MESH_ROOM  # noqa: E402 - tests/ put on the path just above


@pytest.fixture(scope="module")
def ctx():
    context = create_headless_context()
    yield context
    context.release()


def test_straight_edge_error_of_each_sample_count_against_exact_coverage(ctx) -> None:
    errors = straight_edge_errors(ctx, (1, 4, 32))
    # an n x n grid estimates a straight edge's coverage to within about 1/(2n) .. 1/n of the step
    assert errors[1][0] > 0.3  # one ray per pixel: a staircase
    assert errors[4][0] <= 0.15 and errors[4][1] <= 0.04
    assert errors[32][0] <= 0.01 and errors[32][1] <= 0.002


def test_room_edges_take_few_samples_and_the_stimulus_keeps_the_full_grid(ctx) -> None:
    text = (REPO / "protocols" / "egocentric.yaml").read_text()
    # the egocentric study's room and pencil are meshes now: its former box room and analytic pencil here
    assert EGOCENTRIC_MESH_ROOM in text and EGOCENTRIC_MESH_PENCIL in text
    text = text.replace(EGOCENTRIC_MESH_ROOM, EGOCENTRIC_BOX_ROOM).replace(EGOCENTRIC_MESH_PENCIL, "    object: pencil\n")
    protocol = parse_protocol(text, "egocentric.yaml", base_dir=REPO / "protocols")
    row = compile_schedule(protocol, 1).iloc[0].to_dict()
    scene = build_scene(protocol, row, 0.0, np.array([0.032, 0.0, 0.0]), interval=1)
    room = [p for p in scene.primitives if p.edge_samples_per_axis is not None]
    stimulus = [p for p in scene.primitives if p.edge_samples_per_axis is None]
    assert room and stimulus and all(p.edge_samples_per_axis == ROOM_EDGE_SAMPLES_PER_AXIS for p in room)
    full_effort = dataclasses.replace(scene, primitives=tuple(dataclasses.replace(p, edge_samples_per_axis=None)
                                                              for p in scene.primitives))
    cam = make_eye_camera(VIVE_PRO, "right", (0.03, -0.15, -0.6), 0.064, 0.0076916, "ocular")
    target = project_points_px(cam, np.array([p.centre_m for p in stimulus])).mean(axis=0)
    cam = crop_camera(cam, int(target[0]) - 96, int(target[1]) - 64, 192, 128)
    images = {}
    for name, s in (("per primitive", scene), ("full", full_effort)):
        with Renderer(s, RenderSettings(samples_per_axis=16), ctx=ctx) as renderer:
            renderer.render(cam)
            images[name] = renderer.image("right")
            edges = renderer.edge_mask("right")
    differs = np.any(images["per primitive"] != images["full"], axis=-1)
    assert differs.any()  # room edges were sampled differently ...
    assert not differs[~edges].any()  # ... and only edge pixels change
    # ... but never near the stimulus: there the full grid is used
    boxes = project_points_px(cam, np.array([np.array(p.centre_m) + su * np.array(p.half_u_m) + sv * np.array(p.half_v_m)
                                             for p in stimulus for su in (-1, 1) for sv in (-1, 1)]))
    x0, y0 = np.floor(boxes.min(axis=0)).astype(int)  # every pixel the stimulus can reach
    x1, y1 = np.ceil(boxes.max(axis=0)).astype(int)
    assert edges[max(0, y0):y1, max(0, x0):x1].any()
    assert not differs[max(0, y0):y1, max(0, x0):x1].any()


def test_edge_effort_is_validated() -> None:
    with pytest.raises(ValueError, match="edge_samples_per_axis"):
        Primitive(Shape.RECT, (0, 0, -1), (1, 0, 0), (0, 1, 0), Solid((1, 1, 1)), edge_samples_per_axis=0)
