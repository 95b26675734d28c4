"""``psyop simulate``: simulated sessions of every study at the paper's sample sizes."""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from psyop.errors import UserError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "simulate",
        help="simulate all studies' sessions (virtual clock, headless)",
        description="Run simulated sessions (simulated tracker and observer, virtual clock, headless) of "
        "every protocol in PROTOCOLS at the paper's sizes (detection 6, discrimination 6, ordinal 19, "
        "egocentric 13, realism 19 participants). The dataset is marked simulated.",
    )
    parser.add_argument("--data", type=Path, required=True, help="data root to write")
    parser.add_argument("--protocols", type=Path, default=Path("protocols"), help="protocol directory or file")
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), help="worker processes")
    parser.add_argument("--seed", type=int, default=2020, help="base seed of the dataset")
    parser.add_argument("--participants", type=int, default=None, help="participants per study (default: paper sizes)")
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from psyop.run.simulate import PAPER_PARTICIPANTS, simulate_dataset

    paths = sorted(args.protocols.glob("*.yaml")) if args.protocols.is_dir() else [args.protocols]
    if not paths or not all(p.exists() for p in paths):
        raise UserError("no protocol files found", str(args.protocols))
    sizes = {k: args.participants for k in PAPER_PARTICIPANTS} if args.participants else None
    start = time.perf_counter()
    # --participants applies to every study, also those without a paper size (e.g. protocols/examples)
    results = simulate_dataset(paths, args.data, jobs=max(1, args.jobs), base_seed=args.seed, participants=sizes,
                               default_participants=args.participants or 6)
    busy = [r for r in results if r[2].startswith("in use by")]  # another process is simulating it
    bad = [r for r in results if r[2] not in ("complete", "already complete") and r not in busy]
    n_trials = sum(r[3] for r in results)
    print(f"psyop simulate: {len(results)} sessions, {n_trials} new trials in {time.perf_counter() - start:.1f} s "
          f"-> {args.data}", file=sys.stderr)
    if busy:
        print(f"  {len(busy)} sessions were being simulated by another process and were left to it: "
              + ", ".join(f"{s} sub-{p}" for s, p, _, _ in busy[:10]) + (" ..." if len(busy) > 10 else ""),
              file=sys.stderr)
    for study, participant, status, _ in bad:
        print(f"  {study} sub-{participant}: {status}", file=sys.stderr)
    return 1 if bad else 0
