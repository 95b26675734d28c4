"""``psyop validate PROTOCOL...``: check protocol files; errors at file:line:column, exit 2."""

from __future__ import annotations

import argparse
import sys

from psyop.errors import UserError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("validate", help="check protocol YAML files",
                                   description="Check protocol files. Problems are reported as "
                                               "file:line:column with the key and what to change (exit code 2).")
    parser.add_argument("protocol", nargs="+", help="protocol YAML file(s), e.g. protocols/*.yaml")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from psyop.protocol import load_protocol
    from psyop.protocol.plausibility import located_warnings
    from psyop.schedule.counts import trial_count

    paths = args.protocol if isinstance(args.protocol, list) else [args.protocol]
    if len(paths) == 1:  # a single file: let the CLI report the error as usual
        protocol = load_protocol(paths[0])
        for line in located_warnings(protocol):
            print(line, file=sys.stderr)
        print(f"{paths[0]}: ok ({protocol.study.name}: {trial_count(protocol)} trials)")
        return 0
    failed = 0
    for path in paths:
        try:
            protocol = load_protocol(path)
        except UserError as error:
            failed += 1
            print(f"psyop validate: error: {error}", file=sys.stderr)
            continue
        for line in located_warnings(protocol):
            print(line, file=sys.stderr)
        print(f"{path}: ok ({protocol.study.name}: {trial_count(protocol)} trials)")
    return 2 if failed else 0
