"""``psyop run``: run (or resume) one participant session of a protocol."""

from __future__ import annotations

import argparse
from pathlib import Path

from psyop.errors import UserError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "run",
        help="run or resume one session",
        description="Run one participant session of PROTOCOL (resumes after the last recorded trial "
        "if the session exists). Logs go to DATA/<study>/sub-<ID>/ses-<N>/.",
    )
    parser.add_argument("protocol", type=Path, help="protocol YAML file")
    parser.add_argument("--participant", required=True, help="participant ID (letters and digits)")
    parser.add_argument("--session", type=int, default=1, help="session number (default 1)")
    parser.add_argument("--participant-index", type=int, default=None, metavar="N",
                        help="the participant's index for block_order: latin_square (row N mod the square's rows; "
                        "default: the number the participant ID ends in, e.g. S07 -> 7)")
    parser.add_argument("--seed", type=int, default=None, help="schedule/observer seed (default: from IDs, or the session's)")
    parser.add_argument("--tracker", default="sim", help="sim | replay:FILE | pupil:HOST:PORT | serial:DEVICE | openxr "
                        "(eye gaze through the OpenXR runtime, XR_EXT_eye_gaze_interaction; needs --display openxr)")
    parser.add_argument("--pose", default="sim",
                        help="head/hand pose: sim (simulated from the seed) | replay:SESSION_DIR (a logged session with "
                        "the same schedule: protocol, seed, conditions) | replay-by-condition:SESSION_DIR (each trial "
                        "replays a logged trial of the same condition) | openxr (head pose from the OpenXR runtime, needs "
                        "--display openxr) | openxr:HAND (also the hand: left, right or vive_tracker:ROLE)")
    parser.add_argument("--responses", default="sim",
                        help="who answers: sim (the protocol's simulated observer) | keyboard (needs --display window) "
                        "| serial:DEVICE (a response box) | none (nobody: every response phase runs to the protocol's "
                        "timeout_s and is logged as a timeout; a dry run of the timing, needs timeout_s) | openxr (controller "
                        "buttons through the OpenXR runtime, needs --display openxr)")
    parser.add_argument("--display", default="headless", choices=["headless", "window", "openxr"],
                        help="headless (no screen) | window (a desktop window) | openxr (a VR headset through its "
                             "OpenXR runtime: pip install 'psyop[xr]'; docs/headset.md)")
    parser.add_argument("--clock", default="virtual", choices=["virtual", "real"])
    parser.add_argument("--window-scale", type=float, default=0.25, metavar="S",
                        help="--display window: render and show each eye at S x the display's resolution "
                             "(1 = full resolution; both eyes side by side for stereo; default 0.25)")
    parser.add_argument("--data", type=Path, default=Path("data"), help="data root (default data/)")
    parser.add_argument("--render", default="auto", choices=["auto", "images", "cameras"],
                        help="images: ray-cast the stimulus; cameras: eye cameras only; auto: images if OpenGL works")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--allow-protocol-change", action="store_true",
                        help="resume a session with a protocol file whose comments or layout were edited (another "
                        "SHA-256, the same validated values); any change to a value is still refused")
    # testing aids (crash-safety tests): hidden from --help
    parser.add_argument("--phase-delay-s", type=float, default=0.0, help=argparse.SUPPRESS)
    parser.add_argument("--sim-nan-burst-rate-hz", type=float, default=0.0, help=argparse.SUPPRESS)
    parser.add_argument("--sim-dropout-rate-hz", type=float, default=0.0, help=argparse.SUPPRESS)
    parser.add_argument("--xr-request-exit-at-frame", type=int, default=None, help=argparse.SUPPRESS)
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from psyop.protocol import load_protocol
    from psyop.schedule import compile_schedule
    from psyop.session.gaze.simulated import SimulatedTrackerConfig
    from psyop.session.runner import SessionOptions, print_outcome, run_session

    if not args.protocol.exists():
        raise UserError("protocol file not found", str(args.protocol))
    protocol = load_protocol(args.protocol)
    options = SessionOptions(
        participant=args.participant, session=args.session, seed=args.seed, tracker=args.tracker,
        participant_index=args.participant_index,
        responses=args.responses, display=args.display, clock=args.clock, data_root=args.data,
        window_scale=args.window_scale,
        progress=not args.no_progress, allow_protocol_change=args.allow_protocol_change, phase_delay_s=args.phase_delay_s, render=args.render, pose=args.pose,
        xr_request_exit_at_frame=args.xr_request_exit_at_frame,
        tracker_faults=SimulatedTrackerConfig(nan_burst_rate_hz=args.sim_nan_burst_rate_hz,
                                              dropout_rate_hz=args.sim_dropout_rate_hz),
    )
    outcome = run_session(protocol, compile_schedule, options)
    print_outcome(outcome)
    _print_integrity_warnings(args.data, protocol.study.name, args.participant, args.session)
    return outcome.exit_code


def _print_integrity_warnings(data_root: Path, study: str, participant: str, session: int) -> None:
    """What the finalised session.json says about damage and low-gaze trials (stderr)."""
    import sys

    from psyop.cli.recover import describe_integrity
    from psyop.session.log.layout import session_paths
    from psyop.session.log.store import read_metadata

    meta = read_metadata(session_paths(data_root, study, participant, session)) or {}
    for line in describe_integrity(meta.get("integrity") or {}):
        print(f"  {line}", file=sys.stderr)
