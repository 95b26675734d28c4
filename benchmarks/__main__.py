"""Run every benchmark module and write bench/REPORT.md."""

from __future__ import annotations

import argparse
import datetime as dt
import importlib
import pkgutil
import platform
import sys
import time
from pathlib import Path

import benchmarks


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks")
    parser.add_argument("--out", type=Path, default=Path("bench"))
    parser.add_argument("--only", default=None, help="run only modules whose name contains this")
    parser.add_argument("--quick", action="store_true", help="fewer repetitions (smoke run)")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    names = sorted(m.name for m in pkgutil.iter_modules(benchmarks.__path__) if m.name.startswith("bench_"))
    if args.only:
        names = [n for n in names if args.only in n]
    sections = [
        "# psyop benchmark report",
        "",
        f"Run {dt.datetime.now().isoformat(timespec='seconds')} on {platform.node()} "
        f"({platform.machine()}, Python {platform.python_version()}).",
        "Ratios are measured side by side in one run; absolute CPU/llvmpipe times are context only.",
        "",
    ]
    for i, name in enumerate(names, 1):
        print(f"[bench {i}/{len(names)}] {name} ...", file=sys.stderr, flush=True)
        start = time.perf_counter()
        module = importlib.import_module(f"benchmarks.{name}")
        section = module.run(args.out, args.quick)
        sections += [section.rstrip(), "", f"_({name}: {time.perf_counter() - start:.1f} s)_", ""]
    report = args.out / "REPORT.md"
    report.write_text("\n".join(sections) + "\n")
    print(f"wrote {report}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
