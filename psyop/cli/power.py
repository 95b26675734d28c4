"""``psyop power``: study power by simulating whole studies (compile -> session -> analysis)."""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

from typing import TYPE_CHECKING

from psyop.errors import UserError

if TYPE_CHECKING:
    import pandas as pd

    from psyop.power.run import PowerRun, Precision
    from psyop.power.target import TargetSearch


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
    parser.add_argument("--participants", type=_counts, default=None,
                        help="comma-separated sample sizes (default 4,6,8,12,19; not with --target-power)")
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
    parser.add_argument("--target-power", type=float, default=None, metavar="P",
                        help="search the number of participants each test needs for power P (e.g. 0.8): "
                        "bracketing n = MIN, 2 MIN, 4 MIN, ... MAX, then bisection on integers, --replications "
                        "per n; reports n and its interval (docs/adaptive.md)")
    parser.add_argument("--precision", type=float, default=None, metavar="H",
                        help="run as many replications per n as a 95 %% CI half-width of at most H on every test's "
                        "power needs: --replications first, then doubled up to --max-replications (docs/adaptive.md)")
    parser.add_argument("--max-replications", type=int, default=None, metavar="R",
                        help="--precision: the most replications per n (default 1000); an n still less precise is "
                        "flagged")
    parser.add_argument("--min-participants", type=int, default=2, metavar="MIN",
                        help="--target-power: the smallest n tried (default 2)")
    parser.add_argument("--max-participants", type=int, default=40, metavar="MAX",
                        help="--target-power: the largest n tried; a target not reached by then is flagged (default 40)")
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from psyop.power.effects import parse_effects
    from psyop.power.run import PowerRun
    from psyop.power.summary import format_table

    _check_args(args)
    from psyop.power.checkpoint import DEFAULT_DIR

    checkpoint = None if args.no_checkpoint else (
        args.checkpoint or (args.out / "replications" if args.out is not None else DEFAULT_DIR))
    search, precision = _search(args), _precision(args)
    run = PowerRun(protocol_path=args.protocol, participants=args.participants or (4, 6, 8, 12, 19), replications=args.replications,
                   seed=args.seed, effects=parse_effects(args.effect), alpha=args.alpha, scheduler=args.scheduler,
                   jobs=max(1, args.jobs), progress=not args.no_progress and sys.stderr.isatty(),
                   checkpoint=checkpoint, lost_after_s=args.lost_after_s)
    start = time.perf_counter()
    resumed: list[int] = []
    short: list[str] = []
    try:
        table, target, n_studies = _run(run, search, resumed, precision, short)
    except KeyboardInterrupt:
        kept = f"; the finished ones are kept in {checkpoint}/: rerun the same command to resume" if checkpoint else ""
        print(f"psyop power: interrupted{kept}", file=sys.stderr)
        return 130
    where = args.scheduler or f"{run.jobs} local process(es)"
    again = f", {sum(resumed)} of them resumed from {checkpoint}/" if sum(resumed) else ""
    from psyop.power.run import observer_named

    print(f"psyop power: {args.protocol} -- SIMULATED ({observer_named(args.protocol)}), {n_studies} studies{again} "
          f"on {where} in "
          f"{time.perf_counter() - start:.1f} s (seed {args.seed}, alpha {args.alpha:g})")
    print(format_table(table))
    for line in short:
        print(f"psyop power: flag: {line}", file=sys.stderr)
    per_n = (f"{run.replications} replications per n" if precision is None else
             f"replications per n from {run.replications}, doubled up to {precision.max_replications} until every "
             f"95% CI half-width <= {precision.half_width:g}")
    if target is not None and search is not None:
        from psyop.power.target import format_target

        print(f"\ntarget power {search.target_power:g} (bracketing then bisection over n = "
              f"{search.min_participants}..{search.max_participants}, {per_n}):")
        print(format_target(target))
    if args.out is not None:
        _write_outputs(args.out, args.protocol, table, target)
    return 0


def _check_args(args: argparse.Namespace) -> None:
    """One line naming the option for a missing protocol or an option out of its range."""
    if not args.protocol.exists():
        raise UserError("protocol file not found", str(args.protocol))
    if args.replications < 1:
        raise UserError("--replications must be >= 1", "--replications")
    if not 0 < args.alpha < 1:
        raise UserError("--alpha must be in (0, 1)", "--alpha")
    if not args.lost_after_s > 0:
        raise UserError("--lost-after-s must be > 0", "--lost-after-s")


def _write_outputs(out: Path, protocol: Path, table: pd.DataFrame, target: pd.DataFrame | None) -> None:
    """power.csv, target.csv (with --target-power) and power.png in ``out``."""
    from psyop.atomic import write_atomic
    from psyop.figures.output import save_figure
    from psyop.power.figure import plot_power

    out.mkdir(parents=True, exist_ok=True)
    write_atomic(out / "power.csv", table.to_csv(index=False))
    if target is not None:
        write_atomic(out / "target.csv", target.to_csv(index=False))
    save_figure(plot_power(table, f"Power by simulation: {protocol.name}", target), out / "power.png")
    extra = f", {out / 'target.csv'}" if target is not None else ""
    print(f"wrote {out / 'power.csv'}{extra} and {out / 'power.png'}", file=sys.stderr)


def _search(args: argparse.Namespace) -> TargetSearch | None:
    """The --target-power search, validated; None without --target-power."""
    from psyop.power.target import TargetSearch

    if args.target_power is None:
        if args.min_participants != 2 or args.max_participants != 40:
            raise UserError("--min-participants/--max-participants need --target-power", "--max-participants")
        return None
    if args.participants is not None:
        raise UserError("--participants and --target-power exclude each other: the search chooses n "
                        "(bound it with --min-participants/--max-participants)", "--participants")
    return TargetSearch(args.target_power, args.min_participants, args.max_participants)


def _precision(args: argparse.Namespace) -> Precision | None:
    """The --precision rule, validated; None without --precision."""
    from psyop.power.run import Precision

    if args.precision is None:
        if args.max_replications is not None:
            raise UserError("--max-replications needs --precision", "--max-replications")
        return None
    precision = Precision(args.precision, 1000 if args.max_replications is None else args.max_replications)
    if precision.max_replications < args.replications:
        raise UserError(f"--max-replications ({precision.max_replications}) must be >= --replications "
                        f"({args.replications}), the first batch", "--max-replications")
    return precision


def _run(run: PowerRun, search: TargetSearch | None, resumed: list[int], precision: Precision | None,
         short: list[str]) -> tuple[pd.DataFrame, pd.DataFrame | None, int]:
    """The power table, the target table (None without a search) and the number of studies simulated."""
    from psyop.power.run import precise_power, run_power

    if search is None:
        table, results = run_power(run, resumed) if precision is None else precise_power(run, precision, resumed, short)
        return table, None, len(results)
    from psyop.power.target import evaluate_power, search_target

    if precision is None:
        table, target = search_target(run, search, evaluate_power)
    else:
        table, target = search_target(run, search, lambda r, ns: precise_power(replace(r, participants=ns),
                                                                                precision, resumed, short)[0])
    return table, target, int(table.groupby("participants")["n_replications"].max().sum())
