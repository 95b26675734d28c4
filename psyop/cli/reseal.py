"""``psyop reseal SESSION --reason TEXT``: accept a deliberate edit of a finalised session, on record."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from psyop.errors import UserError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "reseal", help="record a deliberate edit of a session's finalised files (new SHA-256, with a reason)",
        description="A finalised session's files (trials.parquet, frames.parquet, ...) must match the SHA-256 "
        "recorded in its session.json, or every reader refuses it. After a deliberate edit, reseal records the "
        "reason, the time and each changed file's old and new SHA-256 in session.json's \"reseals\" list and "
        "accepts the new content. To undo damage instead, delete the file and run `psyop recover` (it rebuilds "
        "the file from the checksummed log).")
    parser.add_argument("session", type=Path, help="session directory (data/<study>/sub-<ID>/ses-<N>)")
    parser.add_argument("--reason", required=True, help="why the files were edited (recorded in session.json)")
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from psyop.finalised import SESSION_METADATA_FILE, read_session_meta, reseal
    from psyop.session.lock import SessionLock
    from psyop.session.log.layout import write_json_atomic

    directory: Path = args.session
    if not directory.is_dir():
        raise UserError("no such session directory", str(directory))
    lock = SessionLock(directory / ".lock")
    lock.acquire("reseal")
    try:
        meta = read_session_meta(directory)
        if meta is None:
            raise UserError("no session.json here: not a finalised psyop session", str(directory))
        record = reseal(meta, directory, args.reason)
        write_json_atomic(directory / SESSION_METADATA_FILE, meta)
    finally:
        lock.release()
    for name, change in record["files"].items():
        old = (change["old_sha256"] or "none")[:12]
        new = (change["new_sha256"] or "none")[:12]
        print(f"{directory}/{name}: {change['change']}, SHA-256 {old} -> {new}", file=sys.stdout)
    print(f"{directory}: resealed ({record['reason']!r} recorded in session.json)", file=sys.stdout)
    return 0
