"""docs/protocols.md examples are valid protocols; the JSON Schema describes the language."""

from __future__ import annotations

import json
import re
from pathlib import Path

from psyop.cli import main
from psyop.cli.schema import protocol_json_schema
from psyop.protocol import parse_protocol
from psyop.schedule import compile_schedule

ROOT = Path(__file__).resolve().parents[2]


def _yaml_blocks() -> list[str]:
    return re.findall(r"```yaml\n(.*?)```", (ROOT / "docs" / "protocols.md").read_text(), flags=re.S)


def test_new_study_in_docs_is_valid_and_compiles() -> None:
    full = [b for b in _yaml_blocks() if b.startswith("psyop_protocol:")]
    assert len(full) == 1
    protocol = parse_protocol(full[0], "docs/protocols.md")
    assert protocol.eyes == "stereo" and protocol.display.eye_model.nc_mm == 7.4
    schedule = compile_schedule(protocol, seed=1)
    assert len(schedule) == 2 * 6 * 40  # back_D x level_D x repetitions
    assert sorted(schedule["level_D"].unique()) == [0, 0.3, 0.6, 0.9, 1.2, 1.5]
    assert schedule.groupby("block")["back_D"].nunique().eq(1).all()
    assert set(schedule["mode_interval1"]) | set(schedule["mode_interval2"]) == {"ocular", "reversed"}


def test_schema_lists_every_kind(tmp_path: Path, capsys) -> None:
    schema = protocol_json_schema()
    text = json.dumps(schema)
    for kind in ("disc", "quad", "sinusoidal_border", "aperture", "grid_planes", "target_field", "fixation_target",
                 "room", "reach_target", "two_interval", "left_right_nearer", "pairwise_preference",
                 "psychometric_2afc", "drift_recalibration", "white_noise", "one_over_f", "image"):
        assert f'"{kind}"' in text, kind
    assert schema["additionalProperties"] is False
    assert set(schema["required"]) >= {"psyop_protocol", "study", "scene", "trial", "design", "response"}
    assert main(["schema", "--out", str(tmp_path / "s.json")]) == 0
    assert json.loads((tmp_path / "s.json").read_text()) == schema


def test_show_summarises_counts_and_duration(capsys) -> None:
    assert main(["show", str(ROOT / "protocols" / "discrimination.yaml")]) == 0
    out = capsys.readouterr().out
    assert "15 x 15 repetitions = 225 trials" in out
    assert "offset_D=3: 0, 0.7, 1.4, 2.1, 2.8" in out
    assert re.search(r"expected duration: \d+\.\d min", out)
