"""``psyop audit PROTOCOL``: render every condition (each interval's mode, each eye, several
gazes) at a reduced scale and check what the participant sees; exit 1 when a check fails."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from psyop.cli.render import ipd_arg_m
from psyop.errors import UserError


def progress_line(done: int, total: int) -> str:
    """The progress line ``psyop audit`` rewrites on stderr.

    Examples
    --------
    >>> progress_line(3, 12)
    'psyop audit: frame 3/12 (25 %)'
    """
    return f"psyop audit: frame {done}/{total} ({100 * done // max(1, total)} %)"


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "audit", help="render every condition and check each primitive's visibility (exit 1 on failure)",
        description="Render every condition of a protocol (one trial each; every interval in its mode, every "
                    "eye, several gazes along the fixation path or on a grid) at a reduced scale with the "
                    "session's renderer, and report per primitive its visible area by mode. Fails (exit 1) when a "
                    "primitive is never visible, when one that exact geometry says is covered shows, when two "
                    "intervals that differ (level, mode) render identically, or when a mesh item's silhouette "
                    "differs from exact ray-triangle intersection beyond the anti-aliasing tolerance.")
    parser.add_argument("protocol", help="protocol YAML file")
    parser.add_argument("--scale", type=float, default=0.125,
                        help="fraction of the display's pixels in each direction (default 0.125)")
    parser.add_argument("--gazes", type=int, default=4, help="gazes per condition, interval and eye (default 4)")
    parser.add_argument("--samples", type=int, default=16,
                        help="rays per axis in edge pixels (S x S; the session uses 32; default 16)")
    parser.add_argument("--seed", type=int, default=0, help="schedule seed that picks each condition's trial")
    parser.add_argument("--ipd-mm", type=float, default=None,
                        help="interpupillary distance when the protocol takes it from the tracker "
                             "(default: the sessions' default, psyop.optics.ranges.DEFAULT_IPD_M)")
    parser.add_argument("--no-progress", action="store_true", help="no progress line on stderr")
    parser.add_argument("--level", type=float, action="append", default=None, metavar="VALUE",
                        help="audit the adaptive factor at this level (repeatable; default: its range's min, "
                             "start and max)")
    parser.add_argument("--sheet", default=None, metavar="PATH.png", help="write a contact sheet of the checked frames, cropped to where the "
                             "scene's primitives are and rendered finer (docs/protocols.md, \"Auditing a protocol\")")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from psyop.audit import AuditSettings, format_table, run_audit, write_contact_sheet
    from psyop.protocol import load_protocol

    if args.sheet is not None and not str(args.sheet).lower().endswith(".png"):
        raise UserError(f"--sheet must name a .png file, got {args.sheet!r}")
    settings = AuditSettings(scale=args.scale, gazes=args.gazes, samples_per_axis=args.samples, ipd_m=ipd_arg_m(args.ipd_mm), seed=args.seed,
                             levels=tuple(args.level or ()), sheet_crop=args.sheet is not None)
    from psyop.mesh.load import MeshFiles

    path = Path(args.protocol)
    mesh_files = MeshFiles(path.parent)  # each model read once: validation and every audited frame
    protocol = load_protocol(path, meshes=mesh_files)
    def show(done: int, total: int) -> None:
        print("\r" + progress_line(done, total), end="\n" if done == total else "", file=sys.stderr, flush=True)

    report = run_audit(protocol, settings, base_dir=path.parent, progress=None if args.no_progress else show,
                       mesh_files=mesh_files)
    print(format_table(report))
    if args.sheet is not None:
        write_contact_sheet(report, Path(args.sheet))
        print(f"wrote contact sheet {args.sheet}")
    return 0 if report.passed else 1
