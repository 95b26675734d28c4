"""Bad protocols give errors a person can act on: file:line:column, the key path, what to do."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from psyop.cli import main
from psyop.errors import UserError
from psyop.protocol import load_protocol, parse_protocol

PROTOCOLS = Path(__file__).resolve().parents[2] / "protocols"
DETECTION = (PROTOCOLS / "detection.yaml").read_text()
REALISM = (PROTOCOLS / "realism.yaml").read_text()


def _line_of(text: str, needle: str) -> int:
    return next(i for i, line in enumerate(text.splitlines(), 1) if needle in line)


def _error(text: str, name: str = "study.yaml", tmp_path: Path | None = None) -> UserError:
    with pytest.raises(UserError) as info:
        parse_protocol(text, name, base_dir=tmp_path)
    return info.value


def _replace(text: str, old: str, new: str) -> str:
    assert old in text, old
    return text.replace(old, new, 1)


CASES = [
    # (name, base, old, new, expected line needle (in the mutated text), key path, words of the hint)
    ("unknown key", DETECTION, "    size_deg: 2 ", "    sise_deg: 2 ", "sise_deg", "scene[0].sise_deg",
     ["unknown key 'sise_deg'", "Did you mean 'size_deg'"]),
    ("unknown top-level key", DETECTION, "observer:\n", "observers:\n", "observers:", "observers",
     ["Did you mean 'observer'"]),
    ("wrong type", DETECTION, "size_deg: 2 ", "size_deg: big ", "size_deg: big", "scene[0].size_deg",
     ["expected a valid number", "'big'"]),
    ("missing field", DETECTION, "  repetitions: 15", "  # no repetitions", "design:", "design",
     ["missing required key 'repetitions'", "add 'repetitions: ...'"]),
    ("negative duration", DETECTION, "duration_s: 0.5", "duration_s: -0.5", "duration_s: -0.5",
     "trial.phases[2].duration_s", ["must be greater than 0", "-0.5", "change the value"]),
    ("unknown kind", DETECTION, "kind: disc", "kind: disk", "kind: disk", "scene[0].kind", ["Did you mean 'disc'"]),
    ("unknown mode", DETECTION, "test: {mode: ocular}", "test: {mode: oculr}", "oculr", "response.test.mode",
     ["Did you mean 'ocular'"]),
    ("unknown eye model", DETECTION, "eye_model: gullstrand_emsley_relaxed", "eye_model: gullstrand_emsly",
     "gullstrand_emsly", "display.eye_model", ["Did you mean 'gullstrand_emsley_relaxed'"]),
    ("unknown factor", DETECTION, "depth: {factor: back_D}  ", "depth: {factor: bak_D}  ", "bak_D",
     "scene[0].depth.factor", ["Did you mean 'back_D'"]),
    ("boolean for a number", DETECTION, "repetitions: 15", "repetitions: yes", "repetitions: yes",
     "design.repetitions", ["boolean"]),
    ("depths in the wrong order", REALISM, "near: {D: 3.5}", "near: {D: 0.2}", "near: {D: 0.2}", "scene[1].near",
     ["wrong order", "swap"]),
    ("too many targets", REALISM, "count: 25 ", "count: 400 ", "count: 400", "scene[1].count",
     ["without overlap", "at most"]),
    ("unitless numeric factor", DETECTION, "    back_D:\n", "    back:\n", "    back:", "design.factors.back",
     ["unit", "_D"]),
    ("duplicate key", DETECTION, "    size_deg: 2 ", "    size_deg: 3\n    size_deg: 2 ", "size_deg: 2 ", "",
     ["duplicate key 'size_deg'", "first written at line"]),
    ("yaml syntax", DETECTION, "levels: [1, 2, 3]", "levels: [1, 2, 3", "level_D:", "",
     ["YAML syntax error", f"it started at line {_line_of(DETECTION, 'levels: [1, 2, 3]')}"]),
    ("tab indentation", DETECTION, "  repetitions: 15", "\trepetitions: 15", "\trepetitions", "", ["tabs"]),
    ("wrong interval count", DETECTION, "    - kind: blank\n      duration_s: 0.5                   # Sec. 5.1: 0.5 s blank frame\n    - kind: interval\n      duration_s: 2                     # Sec. 5.1: 2-second intervals\n",
     "", "  phases:", "trial.phases", ["needs 2 interval phase(s)"]),
    # design mistakes that used to run a whole session for nothing (issue 18)
    ("a factor nothing uses", DETECTION, "    level_D:\n", "    contrast_fraction: {levels: [0.2, 0.8]}\n    level_D:\n",
     "contrast_fraction:", "design.factors.contrast_fraction", ["used by nothing", "look the same on screen", "remove it"]),
    ("observer level column is not the response's", DETECTION, "  level_column: level_D",
     "  level_column: back_D", "level_column: back_D", "observer.level_column",
     ["response's level factor is 'level_D'", "set level_column: level_D"]),
    ("one-level factor for a threshold", DETECTION, "levels: [0, 0.25, 0.5, 0.75, 1]", "levels: [0.5]",
     "levels: [0.5]", "design.factors.level_D.levels", ["has one level", "at least two levels"]),
    ("realism pair in both orders", REALISM, '"ocular|reversed"]', '"ocular|reversed", "ocular|conventional"]',
     "ocular|conventional", "design.factors.pair.levels[3]", ["'conventional|ocular' written in the other order",
                                                               "remove 'ocular|conventional'"]),
]


@pytest.mark.parametrize("name, base, old, new, line_needle, path, words", CASES, ids=[c[0] for c in CASES])
def test_error_points_at_the_problem(name, base, old, new, line_needle, path, words) -> None:
    text = _replace(base, old, new)
    error = _error(text)
    message = str(error)
    assert error.location is not None
    match = re.fullmatch(r"study\.yaml:(\d+):(\d+)", error.location)
    assert match, error.location
    assert int(match.group(1)) == _line_of(text, line_needle), message
    if path:
        assert f"at {path}:" in message
    for word in words:
        assert word in message, message
    assert error.exit_code == 2


def test_missing_texture_file_is_reported_and_found_relative_to_the_protocol(tmp_path: Path) -> None:
    text = _replace(DETECTION, "surface: {kind: solid, rgb: [1, 0, 0]}", "surface: {kind: image, path: tex/red.png}")
    protocol_file = tmp_path / "study.yaml"
    protocol_file.write_text(text)
    with pytest.raises(UserError) as info:
        load_protocol(protocol_file)
    assert info.value.location == f"{protocol_file}:{_line_of(text, 'tex/red.png')}:{text.splitlines()[_line_of(text, 'tex/red.png') - 1].index('tex/red.png') + 1}"
    assert "not found" in str(info.value) and "relative to the protocol file" in str(info.value)
    (tmp_path / "tex").mkdir()
    (tmp_path / "tex" / "red.png").write_bytes(b"\x89PNG")  # a PNG signature and nothing else
    with pytest.raises(UserError) as info:
        load_protocol(protocol_file)
    assert "'tex/red.png' is not a readable image" in str(info.value)
    import matplotlib.image as mpimg
    mpimg.imsave(tmp_path / "tex" / "red.png", [[[1.0, 0.0, 0.0]]])
    assert load_protocol(protocol_file).primitive("back").surface.path == "tex/red.png"


def test_several_problems_are_all_reported() -> None:
    text = _replace(_replace(DETECTION, "size_deg: 2 ", "size_deg: -2 "), "duration_s: 0.5", "duration_s: -1")
    message = str(_error(text))
    assert "scene[0].size_deg" in message and "trial.phases[2].duration_s" in message
    assert message.count("study.yaml:") >= 2


def test_not_utf8_and_missing_file(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_bytes(b"study:\n  name: \xff\xfe\n")
    with pytest.raises(UserError) as info:
        load_protocol(bad)
    assert info.value.location == f"{bad}:2:9" and "UTF-8" in str(info.value)
    with pytest.raises(UserError, match="not found"):
        load_protocol(tmp_path / "nope.yaml")


def test_cli_exit_code_2_without_traceback_in_process(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "study.yaml"
    path.write_text(_replace(DETECTION, "    size_deg: 2 ", "    sise_deg: 2 "))
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path}:{_line_of(path.read_text(), 'sise_deg')}:5" in err and "Did you mean 'size_deg'" in err
    assert "Traceback" not in err
    assert main(["validate", str(PROTOCOLS / "detection.yaml")]) == 0


def test_cli_subprocess_reports_and_exits_2(tmp_path: Path) -> None:
    path = tmp_path / "study.yaml"
    path.write_text(_replace(DETECTION, "duration_s: 0.5", "duration_s: -0.5"))
    for command in (["validate", str(path)], ["show", str(path)],
                    ["compile", str(path), "--seed", "1", "--out", str(tmp_path / "s.parquet")]):
        result = subprocess.run([sys.executable, "-m", "psyop", *command], capture_output=True, text=True,
                                timeout=120)
        assert result.returncode == 2, result.stderr
        assert "Traceback" not in result.stderr
        assert f"{path}:{_line_of(path.read_text(), 'duration_s: -0.5')}:" in result.stderr


def test_validate_many_files_reports_each_and_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(_replace(DETECTION, "size_deg: 2 ", "size_deg: x "))
    paths = [str(p) for p in sorted(PROTOCOLS.glob("*.yaml"))]
    assert main(["validate", *paths]) == 0
    assert main(["validate", paths[0], str(bad), paths[1]]) == 2
    captured = capsys.readouterr()
    assert f"{bad}:{_line_of(bad.read_text(), 'size_deg: x')}:" in captured.err
    assert captured.out.count(": ok (") == len(paths) + 2
