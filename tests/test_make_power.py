"""`make power` runs psyop power for each of the five shipped studies into power/ (ignored by git,
removed by make clean); checked with make's dry run, nothing is simulated here."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _dry(*args: str) -> str:
    return subprocess.run(["make", "--no-print-directory", "-n", "-C", str(REPO), *args],
                          check=True, capture_output=True, text=True).stdout


def test_make_power_covers_every_shipped_protocol(tmp_path: Path) -> None:
    out = tmp_path / "pw"
    recipe = _dry("power-run", f"POWER={out}", "POWER_REPLICATIONS=7")
    sizes = dict(re.findall(r"(\w+):([\d,]+)", recipe.split("for spec in ", 1)[1].split(";", 1)[0]))
    shipped = sorted(p.stem for p in (REPO / "protocols").glob("*.yaml"))
    assert sorted(sizes) == shipped and len(shipped) == 5
    for counts in sizes.values():
        assert len(counts.split(",")) >= 3  # a curve, not a point
    assert "-m psyop power protocols/$name.yaml --participants $sizes --replications 7" in recipe
    assert f'--out "{out}/$name"' in recipe


def test_a_power_folder_with_spaces_is_one_argument(tmp_path: Path) -> None:
    """Every path variable is quoted where it is used (`POWER='a b'` split into two arguments)."""
    out = tmp_path / "power out"
    recipe = _dry("power-run", f"POWER={out}")
    assert f'--out "{out}/$name"' in recipe and f'mkdir -p "{out}/$name"' in recipe


def test_power_output_is_ignored_and_cleaned() -> None:
    assert "/power/" in (REPO / ".gitignore").read_text().splitlines()
    assert re.search(r"rm -rf [^\n]*\bpower\b", _dry("clean"))
