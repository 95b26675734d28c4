"""``psyop run``: run (or resume) one participant session of a protocol."""

from __future__ import annotations

import argparse
import os
import signal
from collections.abc import Mapping
from pathlib import Path

from psyop.errors import UserError
from psyop.run.backends import EXPERIMENTER_WINDOW_HELP, MIRROR_EYES, help_text

#: the experimenter window's default mirror width (pixels; psyop.devices.experimenter.MIRROR_WIDTH_PX, not imported
#: here: the CLI's start-up stays free of the window's modules)
MIRROR_WIDTH_PX = 320


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
    # the backend options' help is generated from the registry (psyop.run.backends)
    parser.add_argument("--tracker", default="sim", help=f"the gaze source: {help_text('tracker')}")
    parser.add_argument("--pose", default="sim", help=f"head/hand pose: {help_text('pose')}")
    parser.add_argument("--responses", default="sim", help=f"who answers: {help_text('responses')}")
    parser.add_argument("--display", default="headless", help=f"where frames go: {help_text('display')}")
    parser.add_argument("--clock", default="virtual", choices=["virtual", "real"])
    parser.add_argument("--lsl-markers", action="store_true",
                        help="publish trial starts, phase onsets, responses and recorded trial ends (trial index, "
                             "condition) as the LSL marker stream 'psyop_markers' for LabRecorder (needs --clock real; "
                             "pip install 'psyop[lsl]'); waits up to --lsl-wait-s for a recorder to connect first")
    parser.add_argument("--lsl-wait-s", type=float, default=10.0, metavar="S",
                        help="--lsl-markers: seconds to wait for a recorder (LabRecorder) to connect before the first "
                             "trial (default 10; the session starts either way and session.json says which)")
    parser.add_argument("--window-scale", type=float, default=0.25, metavar="S",
                        help="--display window: render and show each eye at S x the display's resolution "
                             "(1 = full resolution; both eyes side by side for stereo; default 0.25)")
    parser.add_argument("--experimenter-window", action="store_true", help=EXPERIMENTER_WINDOW_HELP)
    parser.add_argument("--no-mirror", action="store_true",
                        help="no experimenter window, not even the default one of --display openxr")
    parser.add_argument("--mirror-eye", choices=sorted(MIRROR_EYES), default="left",
                        help="the experimenter window mirrors the left eye (default), the right one, or both side by side")
    parser.add_argument("--mirror-width-px", type=int, default=MIRROR_WIDTH_PX, metavar="PX",
                        help=f"each mirrored eye's width in the experimenter window (pixels; default {MIRROR_WIDTH_PX}; "
                             "the height follows the eye image's aspect ratio)")
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
    from psyop.run.runner import SessionOptions, print_outcome, run_session
    from psyop.session.signals import stop_signals_as_interrupt

    if not args.protocol.exists():
        raise UserError("protocol file not found", str(args.protocol))
    from psyop.mesh.load import MeshFiles

    mesh_files = MeshFiles(args.protocol.parent)  # models read once: validation, session.json and the scene
    protocol = load_protocol(args.protocol, meshes=mesh_files)
    options = SessionOptions(
        participant=args.participant, session=args.session, seed=args.seed, tracker=args.tracker,
        participant_index=args.participant_index,
        responses=args.responses, display=args.display, clock=args.clock, data_root=args.data,
        window_scale=args.window_scale, lsl_markers=args.lsl_markers, lsl_wait_s=args.lsl_wait_s,
        progress=not args.no_progress, allow_protocol_change=args.allow_protocol_change, phase_delay_s=args.phase_delay_s, render=args.render, pose=args.pose,
        xr_request_exit_at_frame=args.xr_request_exit_at_frame, mesh_files=mesh_files,
        experimenter_window=mirror_wanted(args.display, args.experimenter_window, args.no_mirror, os.environ),
        experimenter_window_optional=not args.experimenter_window, mirror_eye=args.mirror_eye,
        mirror_width_px=args.mirror_width_px,
        tracker_faults=SimulatedTrackerConfig(nan_burst_rate_hz=args.sim_nan_burst_rate_hz,
                                              dropout_rate_hz=args.sim_dropout_rate_hz),
    )
    # SIGTERM (kill, shutdown) and SIGHUP (terminal closed) end the session as Ctrl-C does
    with stop_signals_as_interrupt() as received:
        outcome = run_session(protocol, compile_schedule, options)
    if received and outcome.status == "interrupted":
        outcome.message = f"{signal.Signals(received[0]).name}: {outcome.message}"
    print_outcome(outcome)
    _print_integrity_warnings(args.data, protocol.study.name, args.participant, args.session)
    return 128 + int(received[0]) if received and outcome.status == "interrupted" else outcome.exit_code


def mirror_wanted(display: str, asked: bool, refused: bool, environ: Mapping[str, str]) -> bool:
    """Whether the session opens the experimenter window: asked for (``--experimenter-window``), else by default
    with a headset display where a desktop display exists ($DISPLAY or $WAYLAND_DISPLAY); never with
    ``--no-mirror`` (asking for both is refused).

    Examples
    --------
    >>> mirror_wanted("openxr", False, False, {"DISPLAY": ":0"}), mirror_wanted("openxr", False, True, {"DISPLAY": ":0"})
    (True, False)
    >>> mirror_wanted("headless", False, False, {"DISPLAY": ":0"}), mirror_wanted("openxr:egl", False, False, {})
    (False, False)
    """
    if asked and refused:
        raise UserError("--experimenter-window and --no-mirror contradict each other: keep one", "--no-mirror")
    if refused:
        return False
    return asked or (display.partition(":")[0] == "openxr"
                     and bool(environ.get("DISPLAY") or environ.get("WAYLAND_DISPLAY")))


def _print_integrity_warnings(data_root: Path, study: str, participant: str, session: int) -> None:
    """What the finalised session.json says about damage and low-gaze trials (stderr)."""
    import sys

    from psyop.cli.recover import describe_integrity
    from psyop.session.log.layout import session_paths
    from psyop.session.log.store import read_metadata

    meta = read_metadata(session_paths(data_root, study, participant, session)) or {}
    for line in describe_integrity(meta.get("integrity") or {}):
        print(f"  {line}", file=sys.stderr)
    line = dropped_frames_warning((meta.get("summary") or {}).get("frame_timing") or {})
    if line:
        print(f"  {line}", file=sys.stderr)


def dropped_frames_warning(frame_timing: dict) -> str:
    """One line when a real-clock run skipped display periods (the display could not keep up: the stimuli
    kept their durations, but fewer frames showed them); '' on the virtual clock or with none skipped.

    Examples
    --------
    >>> dropped_frames_warning({"clock": "real", "n_frames": 300, "dropped_frames": 100,
    ...                         "dropped_frames_by_kind": {"stimulus": 90, "blank": 10}})  # doctest: +ELLIPSIS
    'warning: 100 display periods were skipped (25.0 % of 400; 90 in stimulus phases): ...'
    >>> dropped_frames_warning({"clock": "virtual", "n_frames": 300, "dropped_frames": 0})
    ''
    """
    dropped, shown = int(frame_timing.get("dropped_frames") or 0), int(frame_timing.get("n_frames") or 0)
    if frame_timing.get("clock") != "real" or dropped <= 0:
        return ""
    stimulus = int((frame_timing.get("dropped_frames_by_kind") or {}).get("stimulus", 0))
    return (f"warning: {dropped} display periods were skipped ({100.0 * dropped / (dropped + shown):.1f} % of "
            f"{dropped + shown}; {stimulus} in stimulus phases): the renderer could not keep up with the display; "
            "`psyop timing` on the session shows where, and a protocol `timing: max_dropped_frames` rule marks "
            "the trials (timing_ok)")
