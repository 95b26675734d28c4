"""``psyop validate PROTOCOL``: check a protocol file; errors at file:line:column, exit 2."""

from __future__ import annotations

import argparse

from psyop.protocol import load_protocol
from psyop.schedule import trial_count


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("validate", help="check a protocol YAML file",
                                   description="Check a protocol file. Problems are reported as "
                                               "file:line:column with the key and what to change (exit code 2).")
    parser.add_argument("protocol", help="protocol YAML file, e.g. protocols/detection.yaml")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    protocol = load_protocol(args.protocol)
    print(f"{args.protocol}: ok ({protocol.study.name}: {trial_count(protocol)} trials)")
    return 0
