"""YAML scalars of the wrong type and names that become folder names: located, exit 2."""

from __future__ import annotations

import subprocess
import sys
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
            "!!python/object/apply:os.system ['true']", "!!python/tuple [1]", "!!merge x", "!foo bar",
            "!!pairs {a: 1}", "!!null [1]", "!!int [1]", "!!timestamp [1]", "!foo [1]", "!!value x", "!!yaml x"]


@pytest.mark.parametrize("value", BAD_TAGS)
def test_explicit_yaml_tags_are_one_located_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                 value: str) -> None:
    path = _variant(tmp_path, "  repetitions: 15", f"  repetitions: {value}")
    line = next(i for i, text in enumerate(path.read_text().splitlines(), 1) if "repetitions:" in text)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert f"{path}:{line}:" in err, err


@pytest.mark.parametrize("key", BAD_TAGS)
def test_explicit_yaml_tags_on_keys_are_one_located_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                         key: str) -> None:
    # a tagged key was read before its tag was checked: `!!timestamp foo: 1` was "cannot read a value:
    # 'NoneType' object has no attribute 'groupdict'" with no line, `!!binary x: 1` two lines
    path = _variant(tmp_path, "  repetitions: 15", f"  ? {key}\n  : 1\n  repetitions: 15")
    line = next(i for i, text in enumerate(path.read_text().splitlines(), 1) if text.startswith("  ? "))
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    # `? !!merge x : 1` is a merge whose value (the next line) is not a mapping: located there
    assert f"{path}:{line}:" in err or (key == "!!merge x" and f"{path}:{line + 1}:" in err), err


def test_timestamp_tag_subprocess_exit_2(tmp_path: Path) -> None:
    # the reproduction, as a user runs it
    path = _variant(tmp_path, "  repetitions: 15", "  repetitions: !!timestamp foo")
    result = subprocess.run([sys.executable, "-m", "psyop", "validate", str(path)], capture_output=True, text=True,
                            timeout=120, cwd=ROOT)
    assert result.returncode == 2 and "Traceback" not in result.stderr, result.stderr
    assert result.stderr.count("\n") == 1 and f"{path}:" in result.stderr and "!!timestamp" in result.stderr


def test_plain_tags_still_allowed(tmp_path: Path) -> None:
    # `!!int 15` is the value a plain 15 is; `!!str` keeps a name that looks like a date as text
    path = _variant(tmp_path, "  repetitions: 15", "  repetitions: !!int 15")
    path.write_text(path.read_text().replace("  name: detection", "  name: !!str detection", 1))
    assert main(["validate", str(path)]) == 0
