"""psyop benchmarks (`make bench`).

Each ``benchmarks/bench_*.py`` module exposes ``run(out_dir: pathlib.Path, quick: bool) -> str``
that measures side by side in one run and returns a markdown section. The runner
collects the sections into ``bench/REPORT.md``. Ratios are the claim; absolute times
on this machine's CPU (and llvmpipe) are reported for context only.
"""
