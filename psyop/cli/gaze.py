"""``psyop gaze PATH``: the gaze quality summary of a session or of every session under a data root."""

from __future__ import annotations

import argparse
from pathlib import Path



def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "gaze", help="gaze data quality (loss, accuracy, precision, pursuit gain and lag, saccades) of sessions",
        description="Measures the raw gaze stream of a session (or of every session under a data root) against "
        "the targets its protocol showed, in degrees, with eye-movement events from pymovements (docs/quality.md). "
        "Reads the sessions, changes nothing.")
    parser.add_argument("path", type=Path, help="a session directory (data/<study>/sub-<ID>/ses-<N>) or a data root")
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from psyop.cli._session_dirs import session_dirs
    from psyop.quality.session import measure_session, summary_lines
    from psyop.quality.validation import read_validations, validation_summary_lines

    sessions = session_dirs(args.path)
    for session in sessions:
        measures, _ = measure_session(session)
        print(f"{session}:")
        for line in summary_lines(measures) + validation_summary_lines(read_validations(session)):
            print(f"  {line}")
    return 0
