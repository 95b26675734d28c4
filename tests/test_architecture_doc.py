"""docs/architecture.md's package table names every package and top-level module under psyop/."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_architecture_table_lists_every_package_and_module() -> None:
    doc = (ROOT / "docs" / "architecture.md").read_text()
    rows = set(re.findall(r"^\| `psyop\.(\w+)` \|", doc, flags=re.M))
    src = ROOT / "psyop"
    packages = {p.name for p in src.iterdir() if p.is_dir() and any(p.glob("*.py"))}
    modules = {p.stem for p in src.glob("*.py") if not p.stem.startswith("_")}
    missing = sorted((packages | modules) - rows)
    assert not missing, f"docs/architecture.md has no table row for: {missing}"
