"""``psyop export DATA --bids DIR``: a data root's sessions in a data standard."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "export", help="export a data root's sessions as a BIDS dataset (behaviour and eye tracking)",
        description="Write every finalised session under DATA as a BIDS dataset in DIR (new or empty): per session "
        "and run, the trials as beh events, the gaze as BIDS eye-tracking physio per eye with trial and phase "
        "onsets as physioevents, and psyop's session.json, protocol and parquet files under sourcedata/. Every "
        "session's finalised files are verified first (SHA-256 in session.json): a damaged or edited one is "
        "refused. Check the result with the official validator: bids-validator-deno DIR.")
    parser.add_argument("data", type=Path, nargs="?", default=Path("data"), help="data root (default data/)")
    parser.add_argument("--bids", type=Path, required=True, metavar="DIR", help="directory to write (new or empty)")
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from psyop.export.bids import export_bids

    result = export_bids(args.data, args.bids)
    sources = sorted({s.gaze_source for s in result.sessions})
    print(f"psyop export: {len(result.sessions)} sessions -> {result.root} (BIDS; gaze from the "
          f"{' and '.join(sources)})", file=sys.stdout)
    return 0
