"""``psyop calibrate``: measure a display's transfer function through a photometer (docs/calibration.md).

Shows full-field patches (grey, red, green, blue at ``--levels`` codes, ``--repeats`` times), reads each through
the photometer, fits gain-offset-gamma and a monotone spline per channel and writes the calibration file
(psyop.calibration.record). Any fault: one line naming the device and the fix, exit 2, the readings so far in
``OUT.partial.json``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from psyop.errors import UserError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "calibrate", help="measure a display through a photometer; fit and write its calibration",
        description="Show full-field patches (grey, red, green and blue at --levels codes, --repeats times), read "
                    "each through the photometer, fit gain-offset-gamma and a monotone spline per channel and write "
                    "the calibration (JSON) to --out. A fault (timeout, error reply, garbage, pulled cable, "
                    "non-monotone or noisy readings) ends with one line and exit 2; the readings so far are kept "
                    "in OUT.partial.json.")
    parser.add_argument("--photometer", required=True, metavar="KIND:PORT|manual",
                        help="ls100:PORT, ls110:PORT (Konica Minolta, 4800 7E2), pr650:PORT (Photo Research, 9600 "
                             "8N1), pr655:PORT, pr670:PORT, colorcal:PORT (CRS ColorCAL MKII), or manual (type each reading on "
                             "stdin)")
    parser.add_argument("--display", choices=("headless", "window"), default="window",
                        help="window: full-screen patches on the primary monitor (glfw, the window extra); "
                             "headless: an offscreen EGL framebuffer (tests, emulators; use with --patch-log)")
    parser.add_argument("--patch-log", type=Path, default=None, metavar="FILE",
                        help='append each patch shown as one flushed JSON line {"rgb": [r, g, b]} before the '
                             "photometer is read")
    parser.add_argument("--levels", type=int, default=9, help="codes per channel, 0 to 255 equally spaced (default 9)")
    parser.add_argument("--repeats", type=int, default=1, help="times each patch is measured (default 1)")
    parser.add_argument("--out", type=Path, required=True, metavar="CAL.json", help="the calibration file")
    parser.add_argument("--display-name", default=None, help="the display's name, recorded in the file")
    parser.add_argument("--device-name", default=None, help="manual: the meter the readings come from (recorded)")
    parser.add_argument("--timeout-s", type=float, default=None,
                        help="seconds to wait for each reply (default: LS-100 and ColorCAL 5, PR-6xx 30)")
    parser.add_argument("--settle-s", type=float, default=0.5,
                        help="--display window: seconds each patch shows before it is read (default 0.5)")
    parser.add_argument("--windowed", action="store_true", help="--display window: a 640x480 window, not full screen")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.set_defaults(func=run)


def _checked(args: argparse.Namespace) -> None:
    if args.levels < 4 or args.levels > 256:
        raise UserError(f"--levels must be 4 to 256 (a 3-parameter fit needs 4), got {args.levels}")
    if not 1 <= args.repeats <= 100:
        raise UserError(f"--repeats must be 1 to 100, got {args.repeats}")
    if args.timeout_s is not None and not 0 < args.timeout_s <= 600:
        raise UserError(f"--timeout-s must be in (0, 600], got {args.timeout_s}")
    if not 0 <= args.settle_s <= 60:
        raise UserError(f"--settle-s must be 0 to 60 s, got {args.settle_s}")
    if args.out.suffix != ".json":
        raise UserError(f"--out must name a .json file, got {args.out}")


def _display(args: argparse.Namespace):  # -> a PatchDisplay
    from psyop.calibration.patches import HeadlessPatches, WindowPatches

    if args.display == "headless":
        return HeadlessPatches(args.patch_log)
    return WindowPatches(args.patch_log, fullscreen=not args.windowed, settle_s=args.settle_s)


def run(args: argparse.Namespace) -> int:
    from psyop.calibration.measure import CalibrationPlan, run_calibration
    from psyop.calibration.patches import level_codes
    from psyop.devices.photometers import open_photometer

    _checked(args)
    plan = CalibrationPlan(level_codes(args.levels), args.repeats, args.out, args.display_name)
    photometer = open_photometer(args.photometer, timeout_s=args.timeout_s, device_name=args.device_name)
    try:
        display = _display(args)
        try:
            record = run_calibration(photometer, display, plan, progress=not args.no_progress)
        finally:
            display.close()
    finally:
        photometer.close()
    worst = max(fit["max_abs_residual_relative"] for fit in record["fit"].values())
    models = ", ".join(f"{channel} {fit['model']}" for channel, fit in record["fit"].items())
    lum = record["luminance_cd_m2"]
    print(f"wrote {args.out}: {len(record['readings'])} readings from {record['device']['kind']}, "
          f"{lum['min']:.4g} to {lum['max']:.4g} cd/m2; models {models}; largest residual {100 * worst:.2f} %",
          file=sys.stdout)
    return 0
