"""``psyop sessions DATA``: which sessions a data root holds, per study (simulated or real)."""

from __future__ import annotations

import argparse
from pathlib import Path

from psyop.errors import UserError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "sessions", help="list the sessions of a data root per study (simulated or real)",
        description="Per study: how many sessions, how many simulated (session.json says \"simulated\": true) "
        "and real, how many incomplete. Exit 2 when a study mixes simulated and real sessions, unless --allow-mixed, "
        "and when a session's finalised files do not match the SHA-256 its session.json recorded (damaged or "
        "edited: `psyop reseal` records a deliberate edit).")
    parser.add_argument("data", type=Path, nargs="?", default=Path("data"), help="data root (default data/)")
    parser.add_argument("--allow-mixed", action="store_true", help="accept studies that mix simulated and real sessions")
    parser.add_argument("--require-simulated", action="store_true",
                        help="exit 2 if any session is real (used by `make resimulate` before it deletes anything)")
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from psyop.session.inventory import check_not_mixed, inventory

    # --require-simulated only asks whether anything is real (make resimulate deletes all of it)
    studies = inventory(args.data, verify=not args.require_simulated)
    if not studies:
        print(f"{args.data}/: no sessions")
        return 0
    for study in studies.values():
        print(f"{args.data}/{study.describe()}" + ("  <- MIXED" if study.mixed else ""))
    if args.require_simulated:
        real = [s.describe() for s in studies.values() if s.n_real]
        if real:
            raise UserError(f"holds real sessions ({'; '.join(real)}); nothing was deleted. Move them elsewhere "
                            "first, or re-simulate into another directory: make figures DATA=sim", str(args.data))
    if not args.allow_mixed:
        check_not_mixed(studies, args.data)
    return 0
