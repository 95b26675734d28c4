"""The optics analysis scripts write a non-empty PNG and a PDF beside it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("script", ["fig03_parallax_vs_eccentricity", "supp_linearity"])
def test_script_writes_png_and_pdf(script, tmp_path):
    out = tmp_path / "figures" / f"{script}.png"
    result = subprocess.run([sys.executable, str(ROOT / "analysis" / f"{script}.py"), "--out", str(out)],
                            cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 10_000
    pdf = out.with_suffix(".pdf")
    assert pdf.read_bytes()[:5] == b"%PDF-" and pdf.stat().st_size > 5_000
