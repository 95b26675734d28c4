"""Schedule compilation cost: a 100,000-trial schedule against the 225-trial detection study.

Both are compiled side by side in one run; the report gives the per-trial cost ratio (how well
the compiler scales) and absolute times as context only.
"""

from __future__ import annotations

from pathlib import Path

from benchmarks.timing import median_s
from psyop.protocol import load_protocol, parse_protocol
from psyop.schedule import compile_schedule, write_schedule

PROTOCOLS = Path(__file__).resolve().parents[1] / "protocols"


def scaled_detection_text(n_back: int = 20, n_level: int = 50, repetitions: int = 100) -> str:
    """The detection protocol with n_back x n_level conditions x repetitions trials."""
    text = (PROTOCOLS / "detection.yaml").read_text()
    back = ", ".join(f"{1 + 0.1 * i:.1f}" for i in range(n_back))
    text = text.replace("levels: [1, 2, 3]", f"levels: [{back}]")
    text = text.replace("levels: [0, 0.25, 0.5, 0.75, 1]", f"levels: {{start: 0, step: 0.02, count: {n_level}}}")
    return text.replace("repetitions: 15 ", f"repetitions: {repetitions} ")


def run(out_dir: Path, quick: bool) -> str:
    small = load_protocol(PROTOCOLS / "detection.yaml")
    large = parse_protocol(scaled_detection_text(), "detection_100k.yaml")
    n_small = len(compile_schedule(small, 0))
    n_large = len(compile_schedule(large, 0))
    assert n_large == 100_000, n_large
    repeats_small, repeats_large = (20, 3) if quick else (100, 7)
    t_small = median_s(lambda: compile_schedule(small, 1), repeats_small)
    t_large = median_s(lambda: compile_schedule(large, 1), repeats_large)
    t_parse = median_s(lambda: load_protocol(PROTOCOLS / "detection.yaml"), repeats_small)
    schedule = compile_schedule(large, 1)
    path = out_dir / "schedule_100k.parquet"
    t_write = median_s(lambda: write_schedule(schedule, large, 1, path), 3)
    per_small, per_large = t_small / n_small, t_large / n_large
    return "\n".join([
        "## Schedule compilation (bench_schedule_compile)",
        "",
        "The detection protocol (225 trials) and the same protocol scaled to 20 x 50 conditions x 100",
        f"repetitions ({n_large:,} trials), compiled side by side (median of {repeats_small} / {repeats_large} runs).",
        "",
        "| schedule | trials | compile | per trial |",
        "|---|---:|---:|---:|",
        f"| detection | {n_small} | {t_small * 1e3:.2f} ms | {per_small * 1e6:.2f} us |",
        f"| scaled detection | {n_large:,} | {t_large * 1e3:.1f} ms | {per_large * 1e6:.3f} us |",
        "",
        f"**Per-trial cost ratio (100k / 225): {per_large / per_small:.3f}** (below 1: fixed costs amortise,",
        "the per-trial work is vectorised).",
        f"Context: validating detection.yaml takes {t_parse * 1e3:.1f} ms; writing the 100k schedule to parquet "
        f"{t_write * 1e3:.0f} ms ({path.stat().st_size / 1e6:.1f} MB).",
    ])
