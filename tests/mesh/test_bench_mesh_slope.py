"""benchmarks/bench_mesh_frame.py's slope: a least-squares line through (triangles, ms), per 100k triangles."""

from __future__ import annotations

import pytest

from benchmarks.bench_mesh_frame import TRIANGLES, _slope_lines, slope_per_100k


def test_the_slope_of_a_line_is_its_own():
    counts = list(TRIANGLES)
    assert 1_000_000 in counts
    slope, intercept = slope_per_100k(counts, [2.0 + 0.5 * n / 1e5 for n in counts])
    assert slope == pytest.approx(0.5, rel=1e-9) and intercept == pytest.approx(2.0, rel=1e-9)
    (_, line) = _slope_lines([(n, 2.0 + 0.5 * n / 1e5, 1.0 + 0.25 * n / 1e5) for n in counts])
    assert "0.500 ms per 100k triangles (intercept 2.00 ms), ratio 0.250 per 100k triangles" in line
