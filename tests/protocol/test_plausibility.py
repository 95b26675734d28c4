"""Depths that validate but no eye or display can show get a located warning with the range
(`depth: {D: 50}`, 2 cm, validated and only `psyop audit` noticed); a unitless depth says how to
write the unit."""

from __future__ import annotations

from pathlib import Path

import pytest

from psyop.cli import main

ROOT = Path(__file__).resolve().parents[2]
LINE = "    depth: {D: 0}                       # Sec. 5.2 Conditions: back surface fixed to 0 D"


def _variant(tmp_path: Path, new: str) -> tuple[Path, int]:
    text = (ROOT / "protocols" / "discrimination.yaml").read_text()
    assert LINE in text
    path = tmp_path / "near.yaml"
    path.write_text(text.replace(LINE, new, 1))
    line = next(i for i, t in enumerate(path.read_text().splitlines(), 1) if t == new)
    return path, line


def test_a_depth_nearer_than_an_eye_focuses_is_a_located_warning(tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    path, line = _variant(tmp_path, "    depth: {D: 50}")
    assert main(["validate", str(path)]) == 0  # a warning, not an error: a deliberate near stimulus stays possible
    captured = capsys.readouterr()
    assert captured.err.count("\n") == 1 and f"{path}:{line}:" in captured.err and "warning" in captured.err
    assert "50 D (2.0 cm" in captured.err and "0-10 D" in captured.err and "{m: 50}" in captured.err
    assert ": ok (" in captured.out


def test_factor_levels_reaching_too_near_are_warned(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path, _ = _variant(tmp_path, "    depth: {D: 9.9, factor: [offset_D]}")
    assert main(["validate", str(path)]) == 0
    assert "warning: this depth reaches" in capsys.readouterr().err


def test_shipped_protocols_have_no_warning(capsys: pytest.CaptureFixture[str]) -> None:
    paths = sorted(str(p) for p in [*ROOT.glob("protocols/*.yaml"), *ROOT.glob("protocols/examples/*.yaml")])
    assert main(["validate", *paths]) == 0
    assert "warning" not in capsys.readouterr().err


def test_a_depth_without_unit_suggests_both(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path, line = _variant(tmp_path, "    depth: 1")
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{path}:{line}:" in err and "{D: 1}" in err and "{m: 1}" in err, err
