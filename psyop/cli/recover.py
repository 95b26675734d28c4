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
    from psyop.adaptive.recorded_stop import rebuilt_stop_record
    from psyop.finalised import check_finalised, unfinished_finalisation
    from psyop.session.lock import SessionInUse
    from psyop.session.log.store import expected_trial_count, finalise_session, find_sessions, read_metadata, salvage

    if not args.path.exists():
        raise UserError("no such directory", str(args.path))
    sessions = find_sessions(args.path)
    if not sessions:
        raise UserError("no psyop sessions (session.json) found here", str(args.path))
    errors: list[UserError] = []
    for paths in sessions:
        try:
            meta = read_metadata(paths) or {}
            finalised = paths.trials_parquet.is_file() and paths.frames_parquet.is_file()
            if meta.get("status") == "complete" and finalised and not unfinished_finalisation(meta):
                problems = check_finalised(meta, paths.directory)
                if problems:  # a damaged (or edited) file is not silently overwritten: the user decides
                    raise UserError(f"complete, but {problems[0].describe()}; left untouched: delete the damaged "
                                    "file to rebuild it from the log, or record a deliberate edit with "
                                    f"`psyop reseal {paths.directory} --reason TEXT`", str(paths.directory))
                print(f"{paths.directory}: complete and finalised; left untouched", file=sys.stdout)
                continue
            trials, _ = finalise_session(paths, status="complete", summary=meta.get("summary"),
                                         adaptive_stop=rebuilt_stop_record(meta, salvage(paths).trials))
            meta = read_metadata(paths) or {}
        except SessionInUse as busy:  # another process (a run, or another recover) is finishing it
            print(f"{paths.directory}: in use by {busy.holder}; left to it (not an error)", file=sys.stdout)
            continue
        except UserError as error:
            print(f"psyop recover: error: {error}", file=sys.stderr)
            errors.append(error)
            continue
        n_expected = expected_trial_count(meta)
        not_run = int((meta.get("adaptive_stop") or {}).get("n_trials_not_run", 0))
        state = "complete" if meta.get("status") == "complete" else "incomplete (resumable)"
        stopped = f" ({not_run} more scheduled, not run: adaptive stop rule)" if not_run else ""
        print(f"{paths.directory}: {len(trials)}/{n_expected} trials{stopped}, {state}", file=sys.stdout)
        for line in describe_integrity(meta.get("integrity") or {}):
            print(f"  {line}", file=sys.stdout)
    _describe_dataset(args.path)
    if errors:
        raise UserError(f"{len(errors)} of {len(sessions)} sessions could not be recovered (see above)", str(args.path))
    return 0


def _describe_dataset(path: Path) -> None:
    """Rewrite the data root's dataset_description.json (a run whose disk filled after finalising
    could not): ``path`` is a data root, or a session directory ``ROOT/<study>/sub-*/ses-*``."""
    from psyop.session.log.layout import write_dataset_description

    root = path.parents[2] if path.name.startswith("ses-") and len(path.parents) > 2 else path
    if any(p.is_dir() for p in root.glob("*/sub-*/ses-*")):  # simulated or not: decided from the sessions
        write_dataset_description(root, simulated=True)


def describe_integrity(report: dict) -> list[str]:  # type: ignore[type-arg]
    """Human-readable lines for session.json's ``integrity`` report (empty if all is intact)."""
    lines = []
    lost = report.get("lost_trials") or []
    if lost:
        lines.append(f"lost (damaged) trials, re-run on resume: {lost}")
    frames_lost = report.get("frames_lost_for_trials") or []
    if frames_lost:
        lines.append(f"trials kept whose frame records were damaged (frames missing): {frames_lost}")
    for damage in report.get("damaged_records") or []:
        trial = damage.get("trial")
        what = f"trial {trial}" if trial is not None else "unidentified record"
        lines.append(f"damaged {damage.get('record')} record ({what}, {damage.get('reason')}) in "
                     f"{damage.get('segment')} at byte {damage.get('offset')}, {damage.get('length')} bytes")
    low = report.get("low_gaze_trials") or []
    if low:
        lines.append(f"warning: {len(low)} trials had less than {report.get('min_valid_gaze_share', 0.5):.0%} valid "
                     f"gaze (tracker lost the eye or its clock): {low[:20]}{' ...' if len(low) > 20 else ''}; "
                     "marked gaze_ok false in trials.parquet, kept and counted by the analysis")
    for segment in report.get("torn_segments") or []:
        lines.append(f"{segment}: torn tail (the run was killed mid-record; that trial was not recorded)")
    return lines
