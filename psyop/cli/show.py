"""``psyop show PROTOCOL``: a readable summary (conditions, counts, expected duration), the display's
pixel angles (centre and edge pixels) and, for a blocked design, the block order each of the first N
participants gets."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("show", help="summarise a protocol: conditions, trial counts, duration",
                                   description="Print a readable summary of a protocol. For a blocked design, also "
                                   "the block order of participants S01..SN as `psyop run --participant S0i` (default "
                                   "seed, session 1, participant index from the ID) runs them.")
    parser.add_argument("protocol", help="protocol YAML file")
    parser.add_argument("--participants", type=int, default=None, metavar="N",
                        help="block orders of the first N participants (default: one Latin-square cycle, or 4)")
    parser.set_defaults(func=run)


def participant_orders(protocol, n: int, session: int = 1) -> list[str]:
    """One line per participant S01..S<n>: its blocks in run order (the ``by`` factors' values)."""
    from psyop.protocol.base import format_level
    from psyop.schedule import compile_schedule
    from psyop.schedule.counterbalance import block_sequence, participant_index_from_id
    from psyop.session.gaze.simulated import seed_for

    by = protocol.design.randomisation.by
    lines = []
    for i in range(1, n + 1):
        participant = f"S{i:02d}"
        index = participant_index_from_id(participant)
        schedule = compile_schedule(protocol, seed_for(protocol.study.name, participant, session), participant_index=index)
        blocks = block_sequence(schedule, by)
        text = " -> ".join(", ".join(f"{k}={format_level(v)}" for k, v in b.items()) for b in blocks)
        lines.append(f"    {participant} (participant index {index}): {text}")
    return lines


def run(args: argparse.Namespace) -> int:
    from psyop.errors import UserError
    from psyop.optics.pixels import pixel_angles
    from psyop.protocol import load_protocol, resolve_display_profile
    from psyop.schedule.counterbalance import williams_rows
    from psyop.schedule.summary import summarise

    protocol = load_protocol(args.protocol)
    print(summarise(protocol))
    # the display's pixel angles where they differ most: the axis and the edges (docs/optics.md, "Pixel angles")
    # a stereo protocol shows both eyes, whose frusta are mirror images (asymmetric): print each
    profile = resolve_display_profile(protocol.display)
    for eye in (("left", "right") if protocol.eyes == "stereo" else (protocol.eyes,)):
        print("\n".join(pixel_angles(profile, eye).lines()))
    randomisation = protocol.design.randomisation
    if args.participants is not None and args.participants < 1:
        raise UserError(f"--participants {args.participants}: give 1 or more", "--participants")
    if randomisation.kind == "blocked":
        from psyop.protocol.conditions import expand_conditions

        n_blocks = len({tuple(c[b] for b in randomisation.by) for c in expand_conditions(protocol.design)})
        cycle = len(williams_rows(n_blocks))
        n = args.participants or (cycle if randomisation.block_order == "latin_square" else 4)
        extra = (f"; a Williams square of {n_blocks} blocks repeats every {cycle} participants"
                 if randomisation.block_order == "latin_square" else "")
        print(f"  block order of the first {n} participants ({randomisation.block_order}{extra}):")
        print("\n".join(participant_orders(protocol, n)))
    return 0
