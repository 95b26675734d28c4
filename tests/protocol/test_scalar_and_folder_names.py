"""YAML scalars of the wrong type and names that become folder names: located, exit 2."""

from __future__ import annotations

from pathlib import Path

import pytest

from psyop.cli import main

ROOT = Path(__file__).resolve().parents[2]


def _variant(tmp_path: Path, old: str, new: str) -> Path:
    text = (ROOT / "protocols" / "detection.yaml").read_text()
    assert old in text
    path = tmp_path / "variant.yaml"
    path.write_text(text.replace(old, new, 1))
    return path


@pytest.mark.parametrize(("old", "new", "needle"), [
    ("  name: detection", "  name: " + "a" * 10_000, "at most 64 characters"),  # data/<name>/ is a folder
    ("  name: detection", "  name: 2020-13-45", "as a date"),  # a timestamp-like scalar PyYAML cannot build
    ("  name: detection", "  name: 2020-01-01", "expected a valid string"),
    ("  repetitions: 15", "  repetitions: 2020-01-01 12:00:00", "expected a valid integer"),
])
def test_located_one_line_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str], old: str, new: str,
                                 needle: str) -> None:
    path = _variant(tmp_path, old, new)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and needle in err, err
    assert f"{path}:" in err and len(err) < 400  # located, and a long name is not echoed whole
