"""``psyop schema``: the protocol JSON Schema, for editor completion and checking."""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def protocol_json_schema() -> dict:
    """JSON Schema (draft 2020-12) of a protocol file."""
    from psyop.protocol import Protocol

    schema = Protocol.model_json_schema(mode="validation")
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "psyop protocol"
    return schema


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("schema", help="print the protocol JSON Schema (for editors)",
                                   description="Print the JSON Schema of protocol files. Point your editor's YAML "
                                               "language server at it: '# yaml-language-server: $schema=FILE'.")
    parser.add_argument("--out", type=Path, default=None, help="write to this file instead of stdout")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    text = json.dumps(protocol_json_schema(), indent=2, sort_keys=True) + "\n"
    if args.out is None:
        print(text, end="")
    else:
        from psyop.atomic import write_atomic

        write_atomic(args.out, text)
    return 0
