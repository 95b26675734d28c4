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


#: every explicit YAML tag with a bad value (or one no protocol field takes); `!!timestamp foo` was an
#: AttributeError traceback from PyYAML's timestamp constructor, exit 1
BAD_TAGS = ["!!timestamp foo", "!!binary '@@@'", "!!binary aGVsbG8=", "!!int abc", "!!int 0x", "!!float x",
            "!!bool maybe", "!!set {a: 1}", "!!set [1]", "!!omap [{a: 1}]", "!!omap 3", "!!pairs [[1, 2]]",
            "!!str [1]", "!!seq {a: 1}", "!!map [1]", "!!python/object:os.system x", "!!python/name:os.system x",
            "!!python/object/apply:os.system ['true']", "!!python/tuple [1]", "!!merge x", "!foo bar"]


@pytest.mark.parametrize("value", BAD_TAGS)
def test_explicit_yaml_tags_are_one_located_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                 value: str) -> None:
    path = _variant(tmp_path, "  repetitions: 15", f"  repetitions: {value}")
    line = next(i for i, text in enumerate(path.read_text().splitlines(), 1) if "repetitions:" in text)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert f"{path}:{line}:" in err, err


def test_plain_tags_still_allowed(tmp_path: Path) -> None:
    # `!!int 15` is the value a plain 15 is; `!!str` keeps a name that looks like a date as text
    path = _variant(tmp_path, "  repetitions: 15", "  repetitions: !!int 15")
    path.write_text(path.read_text().replace("  name: detection", "  name: !!str detection", 1))
    assert main(["validate", str(path)]) == 0
