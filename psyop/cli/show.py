"""``psyop show PROTOCOL``: a readable summary (conditions, counts, expected duration)."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("show", help="summarise a protocol: conditions, trial counts, duration",
                                   description="Print a readable summary of a protocol.")
    parser.add_argument("protocol", help="protocol YAML file")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from psyop.protocol import load_protocol
    from psyop.schedule.summary import summarise

    print(summarise(load_protocol(args.protocol)))
    return 0
