"""``psyop show PROTOCOL``: a readable summary (conditions, counts, expected duration) and the display's
pixel angles (centre and edge pixels)."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("show", help="summarise a protocol: conditions, trial counts, duration",
                                   description="Print a readable summary of a protocol.")
    parser.add_argument("protocol", help="protocol YAML file")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from psyop.optics.pixels import pixel_angles
    from psyop.protocol import load_protocol, resolve_display_profile
    from psyop.schedule.summary import summarise

    protocol = load_protocol(args.protocol)
    print(summarise(protocol))
    # the display's pixel angles where they differ most: the axis and the edges (docs/optics.md, "Pixel angles")
    eye = protocol.eyes if protocol.eyes in ("left", "right") else "right"
    print("\n".join(pixel_angles(resolve_display_profile(protocol.display), eye).lines()))
    return 0
