"""``psyop power``: study power by simulating whole studies (compile -> session -> analysis)."""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from psyop.errors import UserError


def _counts(text: str) -> tuple[int, ...]:
    try:
        counts = tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give participant counts like 4,6,8,12,19") from None
    if not counts or min(counts) < 2 or len(set(counts)) != len(counts):
        raise argparse.ArgumentTypeError(f"{text!r}: need distinct counts >= 2")
    return counts


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "power",
        help="power by simulation: the share of simulated studies whose tests reach p < alpha",
        description="Simulate REPLICATIONS whole studies per participant count through the real compile, "
        "session (simulated tracker and observer, virtual clock, headless) and analysis path, and report for "
        "every test the study reports the share of replications with p < alpha and its 95 %% Clopper-Pearson CI. "
        "Each replication is seeded on its own (numpy SeedSequence), so the result is the same on local "
        "processes and on a Dask cluster (--scheduler). See docs/adaptive.md.",
    )
    parser.add_argument("protocol", type=Path, help="protocol YAML with an observer: section")
    parser.add_argument("--participants", type=_counts, default=(4, 6, 8, 12, 19), help="comma-separated sample sizes")
    parser.add_argument("--replications", type=int, default=100, help="simulated studies per sample size")
    parser.add_argument("--effect", action="append", default=[], metavar="KEY=VALUE",
                        help="set an observer parameter, e.g. threshold_slope=0.05 (repeatable)")
    parser.add_argument("--alpha", type=float, default=0.05)
    parser.add_argument("--seed", type=int, default=0, help="seed of the whole run")
    parser.add_argument("--out", type=Path, default=None, help="write OUT/power.csv and OUT/power.png")
    parser.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                        help="run replications on this Dask scheduler instead of local processes")
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), help="local worker processes")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--checkpoint", type=Path, default=None, metavar="DIR",
                        help="keep each finished replication in DIR; a rerun with the same arguments resumes them "
                        "(default: OUT/replications with --out, else .psyop-power)")
    parser.add_argument("--no-checkpoint", action="store_true", help="keep no replications (nothing resumes)")
    parser.add_argument("--lost-after-s", type=float, default=60.0, metavar="S",
                        help="--scheduler: a cluster without any worker for S seconds is lost (exit 3; default 60)")
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from psyop.power.effects import parse_effects
    from psyop.power.run import PowerRun, run_power
    from psyop.power.summary import format_table

    if not args.protocol.exists():
        raise UserError("protocol file not found", str(args.protocol))
    if args.replications < 1:
        raise UserError("--replications must be >= 1", "--replications")
    if not 0 < args.alpha < 1:
        raise UserError("--alpha must be in (0, 1)", "--alpha")
    if not args.lost_after_s > 0:
        raise UserError("--lost-after-s must be > 0", "--lost-after-s")
    from psyop.power.checkpoint import DEFAULT_DIR

    checkpoint = None if args.no_checkpoint else (
        args.checkpoint or (args.out / "replications" if args.out is not None else DEFAULT_DIR))
    run = PowerRun(protocol_path=args.protocol, participants=args.participants, replications=args.replications,
                   seed=args.seed, effects=parse_effects(args.effect), alpha=args.alpha, scheduler=args.scheduler,
                   jobs=max(1, args.jobs), progress=not args.no_progress and sys.stderr.isatty(),
                   checkpoint=checkpoint, lost_after_s=args.lost_after_s)
    start = time.perf_counter()
    resumed: list[int] = []
    try:
        table, results = run_power(run, resumed)
    except KeyboardInterrupt:
        kept = f"; the finished ones are kept in {checkpoint}/: rerun the same command to resume" if checkpoint else ""
        print(f"psyop power: interrupted{kept}", file=sys.stderr)
        return 130
    where = args.scheduler or f"{run.jobs} local process(es)"
    again = f", {resumed[0]} of them resumed from {checkpoint}/" if resumed and resumed[0] else ""
    print(f"psyop power: {args.protocol} -- SIMULATED, {len(results)} studies{again} on {where} in "
          f"{time.perf_counter() - start:.1f} s (seed {args.seed}, alpha {args.alpha:g})")
    print(format_table(table))
    if args.out is not None:
        from psyop.figures.output import save_figure
        from psyop.power.figure import plot_power

        args.out.mkdir(parents=True, exist_ok=True)
        from psyop.atomic import write_atomic

        write_atomic(args.out / "power.csv", table.to_csv(index=False))
        save_figure(plot_power(table, f"Power by simulation: {args.protocol.name}"), args.out / "power.png")
        print(f"wrote {args.out / 'power.csv'} and {args.out / 'power.png'}", file=sys.stderr)
    return 0
