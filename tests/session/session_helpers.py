"""Helpers for session tests: small copies of the real protocols."""

from __future__ import annotations

import re
from pathlib import Path

PROTOCOLS = Path(__file__).resolve().parents[2] / "protocols"


def small_protocol(directory: Path, study: str, repetitions: int = 1) -> Path:
    """A copy of protocols/<study>.yaml with ``repetitions`` per condition (fewer trials)."""
    text = (PROTOCOLS / f"{study}.yaml").read_text()
    text, n = re.subn(r"(?m)^(\s*repetitions:)\s*\d+", rf"\g<1> {repetitions}", text)
    assert n == 1, f"{study}.yaml: no repetitions line to shrink"
    path = directory / f"{study}_small.yaml"
    path.write_text(text)
    return path
