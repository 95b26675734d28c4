"""Validation refuses a scene the renderer could not draw (more than MAX_PRIMITIVES primitives in a
phase), with the scene item's file:line, the count, the limit and the fix; the per-kind counts it
uses match what the stimulus builder builds."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest

from psyop.errors import UserError
from psyop.limits import MAX_PRIMITIVES
from psyop.protocol import parse_protocol
from psyop.protocol.primitive_count import primitive_count
from psyop.rendering import shaders
from psyop.schedule import compile_schedule
from psyop.stimulus import build_scene

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from protocol_texts import EGOCENTRIC_BOX_ROOM, EGOCENTRIC_MESH_PENCIL, EGOCENTRIC_MESH_ROOM

PROTOCOLS = Path(__file__).resolve().parents[2] / "protocols"
REALISM = (PROTOCOLS / "realism.yaml").read_text()
GRID_PLANES = 4  # realism.yaml's grid: floor, ceiling, left, right


def _realism_with(count: int) -> str:
    text = REALISM.replace("count: 25 ", f"count: {count} ", 1).replace("size_deg: 2.6 ", "size_deg: 1.0 ", 1)
    assert f"count: {count} " in text
    return text


def test_renderer_and_validation_share_one_limit() -> None:
    assert shaders.MAX_PRIMITIVES is MAX_PRIMITIVES


def test_target_field_of_200_is_refused_at_its_line() -> None:
    text = _realism_with(200)
    with pytest.raises(UserError) as info:
        parse_protocol(text, "study.yaml")
    message = str(info.value)
    line = next(i for i, s in enumerate(text.splitlines(), 1) if "count: 200" in s)
    assert re.fullmatch(rf"study\.yaml:{line}:\d+", info.value.location or ""), (info.value.location, message)
    assert "scene[1].count" in message
    assert f"{200 + GRID_PLANES} primitives" in message and f"limit of {MAX_PRIMITIVES}" in message
    assert f"lower count to at most {MAX_PRIMITIVES - GRID_PLANES}" in message
    assert info.value.exit_code == 2


def test_scene_just_at_the_limit_validates_and_builds() -> None:
    protocol = parse_protocol(_realism_with(MAX_PRIMITIVES - GRID_PLANES), "study.yaml")
    row = compile_schedule(protocol, seed=1).iloc[0].to_dict()
    scene = build_scene(protocol, row, 0.0, np.array([0.032, 0.0, 0.0]), interval=1)
    assert len(scene.primitives) == MAX_PRIMITIVES


def test_blank_phase_shows_only_its_items() -> None:
    # the blank shows only the grid; the intervals show all: the limit is per phase
    protocol = parse_protocol(_realism_with(MAX_PRIMITIVES - GRID_PLANES), "study.yaml")
    assert sum(primitive_count(item) for item in protocol.scene) == MAX_PRIMITIVES


VARIANTS = [  # (protocol, old, new): every kind and every branch of primitive_count
    ("detection", "", ""), ("discrimination", "", ""), ("egocentric", "", ""), ("ordinal", "", ""),
    ("realism", "", ""),
    ("detection", "    kind: disc\n    size_deg: 2   ", "    kind: quad\n    width_deg: 2\n    height_deg: 1\n    # size_deg: 2 "),
    ("egocentric", EGOCENTRIC_MESH_PENCIL, "    object: pencil\n"),  # the analytic pencil the mesh one replaced
    ("egocentric", EGOCENTRIC_MESH_PENCIL, "    object: sphere\n"),
    ("egocentric", EGOCENTRIC_MESH_PENCIL, "    object: cube\n"),
    ("egocentric", EGOCENTRIC_MESH_ROOM, EGOCENTRIC_BOX_ROOM),
    ("egocentric", EGOCENTRIC_MESH_ROOM, EGOCENTRIC_BOX_ROOM.replace("    table_height_m: 0.75\n", "")),
]


@pytest.mark.parametrize("name, old, new", VARIANTS)
def test_counts_match_the_built_scene(name: str, old: str, new: str) -> None:
    text = (PROTOCOLS / f"{name}.yaml").read_text()
    assert old in text
    text = text.replace(old, new, 1)
    protocol = parse_protocol(text, f"{name}.yaml", base_dir=PROTOCOLS)
    row = compile_schedule(protocol, seed=3).iloc[0].to_dict()
    scene = build_scene(protocol, row, 0.0, np.array([0.032, 0.0, 0.0]), interval=1, show=[i.id for i in protocol.scene],
                        base_dir=PROTOCOLS)
    for item in protocol.scene:
        built = [p for p in scene.primitives if p.name == item.id or p.name.startswith(f"{item.id}_")]
        assert len(built) == primitive_count(item), item.id
