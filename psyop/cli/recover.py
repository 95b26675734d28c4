"""``psyop recover``: finalise crashed sessions from their durable streams (no new trials)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from psyop.errors import UserError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "recover",
        help="finalise crashed sessions without running more trials",
        description="Rebuild trials.parquet and frames.parquet from the per-trial log streams of every "
        "session under PATH (a data root or one session directory). A torn last record is dropped. "
        "The session stays resumable with `psyop run` if it is incomplete.",
    )
    parser.add_argument("path", type=Path, help="data root or session directory")
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from psyop.session.log.store import finalise_session, find_sessions

    if not args.path.exists():
        raise UserError("no such directory", str(args.path))
    sessions = find_sessions(args.path)
    if not sessions:
        raise UserError("no psyop sessions (session.json) found here", str(args.path))
    for paths in sessions:
        import json

        meta = json.loads(paths.metadata.read_text())
        trials, _ = finalise_session(paths, status="complete", summary=meta.get("summary"))
        n_expected = meta.get("n_trials_scheduled")
        state = "complete" if n_expected is not None and len(trials) >= int(n_expected) else "incomplete (resumable)"
        print(f"{paths.directory}: {len(trials)}/{n_expected} trials, {state}", file=sys.stdout)
    return 0
