"""``psyop compile PROTOCOL --seed N --out schedule.parquet``: write the trial schedule."""

from __future__ import annotations

import argparse
from pathlib import Path

from psyop.errors import UserError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("compile", help="compile a protocol into a seeded trial schedule (parquet)",
                                   description="Compile a protocol into a trial schedule. The same protocol and "
                                               "seed always give byte-identical output.")
    parser.add_argument("protocol", help="protocol YAML file")
    parser.add_argument("--seed", type=int, required=True, help="non-negative integer seed")
    parser.add_argument("--out", type=Path, required=True, help="output .parquet file")
    parser.add_argument("--participant-index", type=int, default=None, metavar="N",
                        help="participant index for block_order: latin_square (required there; ignored otherwise)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from psyop.protocol import load_protocol
    from psyop.schedule import compile_schedule, write_schedule

    protocol = load_protocol(args.protocol)
    schedule = compile_schedule(protocol, args.seed, participant_index=args.participant_index)
    if not args.out.parent.exists():
        raise UserError(f"output folder {args.out.parent} does not exist; create it first")
    try:
        write_schedule(schedule, protocol, args.seed, args.out)
    except OSError as error:
        raise UserError(f"cannot write {args.out}: {error.strerror or error}") from None
    print(f"wrote {args.out}: {len(schedule)} trials, {schedule['condition'].nunique()} conditions, seed {args.seed}")
    return 0
