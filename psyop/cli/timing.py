"""``psyop timing PATH``: the measured timing of a session, or of every session under a data root.

Prints each session's summary (frame intervals against the refresh period, dropped frames in total and
per phase kind, each phase's measured against its nominal duration) and draws its figure (frame-interval
histogram with the refresh period marked, dropped frames per trial, measured against nominal phase
durations) into ``--out`` as ``timing_<study>_sub-<ID>_ses-<N>.png`` (and .pdf). Reads the sessions,
changes nothing (docs/sessions.md "Timing").
"""

from __future__ import annotations

import argparse
from pathlib import Path

from psyop.errors import UserError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "timing", help="measured frame timing of sessions: intervals, dropped frames, phase durations; a figure each",
        description="Prints the measured timing of a session (or of every session under a data root): frame "
        "intervals against the refresh period, dropped frames in total and per phase kind, each phase's measured "
        "against its nominal duration; and writes a figure per session. Reads the sessions, changes nothing.")
    parser.add_argument("path", type=Path, help="a session directory (data/<study>/sub-<ID>/ses-<N>) or a data root")
    parser.add_argument("--out", type=Path, default=Path("figures"),
                        help="folder for the figures, timing_<study>_sub-<ID>_ses-<N>.png/.pdf (default: figures)")
    parser.add_argument("--skip-simulated", action="store_true",
                        help="only real sessions (session.json simulated: false): what `make figures` draws")
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from psyop.cli._session_dirs import session_dirs
    import pandas as pd

    from psyop import datacontract as dc
    from psyop.session.log.record import read_record_file
    from psyop.figures.timing_figures import timing_figure
    from psyop.session.timing import session_report

    path: Path = args.path
    sessions = session_dirs(path)
    drawn = 0
    for session in sessions:
        record = read_record_file(session / dc.SESSION_METADATA_FILE)
        if record is None:
            raise UserError("no session.json beside trials.parquet: run `psyop recover` on this session", str(session))
        if args.skip_simulated and record.simulated is not False:  # not recorded: not known to be real
            continue
        frames_file = session / "frames.parquet"
        if not frames_file.is_file():
            raise UserError("no frames.parquet: the session is not finalised; run `psyop recover` on it", str(session))
        frames = pd.read_parquet(frames_file)
        missing = sorted({"trial", "frame", "phase", dc.DISPLAY_TIME_S, dc.DISPLAY_MISSED_FRAMES} - set(frames.columns))
        if missing:
            raise UserError(f"frames.parquet has no {', '.join(missing)}: recorded by a psyop that did not log display "
                            "times, so its timing cannot be measured", str(frames_file))
        report = session_report(str(session), dict(record.raw), pd.read_parquet(session / dc.TRIALS_FILE), frames)
        print(f"{session}:")
        for line in report.lines():
            print(f"  {line}")
        name = f"timing_{record.study or session.parent.parent.name}_{session.parent.name}_{session.name}.png"
        for written in timing_figure(report, args.out / name)[:1]:
            print(f"  figure: {written}")
        drawn += 1
    if not drawn:
        print(f"psyop timing: no real sessions under {path} (simulated ones are skipped): no timing figure")
    return 0
