"""``psyop render PROTOCOL``: render one frame of one trial to an 8-bit PNG plus a JSON sidecar.

The sidecar records what the frame is: centre of projection in head space, frustum tangents
seen from it, resolution, eye model, eye, mode, gaze, trial and interval.
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from psyop.errors import UserError

if TYPE_CHECKING:
    import numpy as np

    from psyop.mesh.load import MeshFiles
    from psyop.optics import DisplayProfile, EyeModel
    from psyop.optics.camera import EyeCamera
    from psyop.protocol.model import Protocol
    from psyop.rendering.scene import Scene


#: ``--phase`` values that draw a screen of the protocol's ``session:`` (psyop.session.screens)
SCREEN_PHASES: tuple[str, ...] = ("instructions", "break", "questionnaire", "end", "feedback")


def ipd_arg_m(ipd_mm: float | None) -> float:
    """``--ipd-mm`` in metres, checked against psyop.optics.ranges.IPD_M (None: DEFAULT_IPD_M; imported
    here, not at parser build, so that ``psyop --help`` stays light)."""
    from psyop.optics.ranges import DEFAULT_IPD_M, IPD_M

    if ipd_mm is None:
        return DEFAULT_IPD_M
    if not IPD_M.contains(ipd_mm / 1000.0):
        raise UserError(f"--ipd-mm must be in {IPD_M.describe(1000.0, 'mm')}, got {ipd_mm:g}")
    return ipd_mm / 1000.0



def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "render", help="render one frame of a trial to PNG (+ JSON sidecar)",
        description="Render the stimulus of trial N, interval K, for a given gaze direction, to an 8-bit PNG. "
                    "Headless (EGL); no display needed.")
    parser.add_argument("protocol", help="protocol YAML file")
    parser.add_argument("--trial", type=int, default=0, help="trial number (0-based, execution order)")
    parser.add_argument("--interval", type=int, default=1, help="interval phase of the trial (1-based)")
    parser.add_argument("--phase", choices=("interval", "response", *SCREEN_PHASES), default="interval",
                        help="interval: the stimulus of --interval; response: what the participant sees while "
                             "answering (the prompt, else the question, on a head-fixed panel; conventional mode); "
                             "instructions, break, questionnaire, end: screen --screen of the protocol's session: "
                             "section on the same panel (a break as after its first every_trials trials)")
    parser.add_argument("--screen", type=int, default=0, metavar="N",
                        help="which screen of --phase instructions|break|questionnaire|end (0-based: an "
                             "instruction page, a questionnaire item in the order the questionnaires are listed)")
    gaze = parser.add_mutually_exclusive_group()
    gaze.add_argument("--gaze-deg", default=None, metavar="AZ,EL",
                      help="gaze direction from the rendered eye's centre of rotation as Fick angles, degrees "
                           "(azimuth right-positive about the vertical axis, then elevation up-positive; "
                           "docs/optics.md, 'Angles'); |AZ|, |EL| < 89; default 0,0")
    gaze.add_argument("--gaze-polar-deg", default=None, metavar="ECC,MERIDIAN",
                      help="the gaze direction in the polar form instead: eccentricity from straight ahead (< 89) "
                           "and meridian (0 right, 90 up)")
    parser.add_argument("--fixation-m", type=float, default=1.0,
                        help="distance of the fixated point (m, more than 0.02)")
    parser.add_argument("--eye", choices=("right", "left"), default=None,
                        help="eye to render (default: the protocol's eye; right for stereo)")
    parser.add_argument("--mode", choices=("conventional", "ocular", "reversed"), default=None,
                        help="rendering mode (default: the interval's mode from the schedule)")
    parser.add_argument("--time-s", type=float, default=0.0, help="time into the interval (moving targets)")
    parser.add_argument("--seed", type=int, default=0, help="schedule seed")
    parser.add_argument("--participant-index", type=int, default=0, metavar="N",
                        help="participant index for block_order: latin_square (default 0; trial numbers follow its order)")
    parser.add_argument("--level", type=float, default=None, metavar="VALUE",
                        help="the adaptive factor's level for this trial (an adaptive protocol's level is chosen "
                             "while the session runs; default: the procedure's start level)")
    parser.add_argument("--ipd-mm", type=float, default=None,
                        help="interpupillary distance when the protocol takes it from the tracker "
                             "(default: the sessions' default, psyop.optics.ranges.DEFAULT_IPD_M)")
    parser.add_argument("--antialiasing", choices=("adaptive", "none", "msaa", "supersample"), default="adaptive")
    parser.add_argument("--crop", default=None, metavar="X0,Y0,W,H",
                        help="render only this pixel window of the full frame (same rays as the full frame)")
    parser.add_argument("--out", required=True, help="output PNG path (the sidecar is PATH.json)")
    parser.set_defaults(func=run)


def _parse_pair(option: str, text: str, names: str) -> tuple[float, float]:
    try:
        a, b = (float(x) for x in text.split(","))
    except ValueError:
        raise UserError(f"{option} must be {names} in degrees, got {text!r}") from None
    if not (math.isfinite(a) and math.isfinite(b)):
        raise UserError(f"{option} must be finite, got {text!r}")
    return a, b


def parse_gaze(gaze_deg: str | None, gaze_polar_deg: str | None) -> tuple[float, float]:
    """Fick (azimuth, elevation) of ``--gaze-deg AZ,EL`` or ``--gaze-polar-deg ECC,MERIDIAN``."""
    from psyop.stimulus.placement import polar_centre_deg

    if gaze_polar_deg is not None:
        ecc, meridian = _parse_pair("--gaze-polar-deg", gaze_polar_deg, "ECC,MERIDIAN")
        if not 0.0 <= ecc < 89.0:
            raise UserError(f"--gaze-polar-deg eccentricity must be in [0, 89) deg, got {gaze_polar_deg!r}")
        return polar_centre_deg(ecc, meridian)
    text = "0,0" if gaze_deg is None else gaze_deg
    az, el = _parse_pair("--gaze-deg", text, "AZ,EL")
    if not (abs(az) < 89 and abs(el) < 89):
        raise UserError(f"--gaze-deg must be within +-89 deg, got {text!r}")
    return az, el


def _parse_crop(text: str, width_px: int, height_px: int) -> tuple[int, int, int, int]:
    try:
        x0, y0, w, h = (int(x) for x in text.split(","))
    except ValueError:
        raise UserError(f"--crop must be X0,Y0,W,H in whole pixels, got {text!r}") from None
    if not (0 <= x0 and 0 <= y0 and w > 0 and h > 0 and x0 + w <= width_px and y0 + h <= height_px):
        raise UserError(f"--crop {text} does not fit the {width_px}x{height_px} frame")
    return x0, y0, w, h


def _adaptive_level(protocol, given: float | None) -> float | None:
    """The level an adaptive protocol's trial is rendered at: ``--level`` (checked against the
    procedure's range), else the start level; None for fixed levels (``--level`` is then an error)."""
    from psyop.adaptive.session import preview_levels

    if given is not None:
        return preview_levels(protocol, (given,))[0]
    factors = [f for f in protocol.design.factors.values() if f.adaptive is not None]
    return float(factors[0].adaptive.start) if factors else None


def frustum_tangents(pixel_to_ray: np.ndarray) -> dict[str, float]:
    """Left/right/bottom/top tangents of the image seen from the centre of projection."""
    import numpy as np

    m = np.asarray(pixel_to_ray, dtype=np.float64)
    corner = lambda u, v: m @ np.array([u, v, 1.0])  # noqa: E731
    tl, br = corner(0.0, 0.0), corner(1.0, 1.0)
    return {"left": tl[0] / -tl[2], "right": br[0] / -br[2], "bottom": br[1] / -br[2], "top": tl[1] / -tl[2]}


def write_png(path: Path, image_uint8: np.ndarray) -> None:
    """8-bit RGB PNG via matplotlib (already a dependency)."""
    import matplotlib.image as mpimg

    from psyop.atomic import write_atomic

    write_atomic(path, lambda handle: mpimg.imsave(handle, image_uint8, format="png"))


def _checked_trial(args: argparse.Namespace, protocol: Protocol) -> tuple[dict, float | None, tuple[float, float]]:
    """The schedule row of ``--trial`` (at the adaptive level, if any), that level and the gaze's
    Fick angles; the trial, interval, fixation and gaze options are checked in this order."""
    from psyop.schedule import compile_schedule
    from psyop.stimulus import interval_phases

    schedule = compile_schedule(protocol, args.seed, participant_index=args.participant_index)
    if not 0 <= args.trial < len(schedule):
        raise UserError(f"--trial must be in 0..{len(schedule) - 1}, got {args.trial}")
    n_intervals = len(interval_phases(protocol))
    if not 1 <= args.interval <= max(1, n_intervals):
        raise UserError(f"--interval must be in 1..{n_intervals}, got {args.interval}")
    if not (math.isfinite(args.fixation_m) and args.fixation_m > 0.02):
        raise UserError(f"--fixation-m must be more than 0.02 m, got {args.fixation_m}")
    gaze_deg = parse_gaze(args.gaze_deg, args.gaze_polar_deg)
    row = schedule.iloc[args.trial].to_dict()
    level = _adaptive_level(protocol, args.level)
    if level is not None:
        from psyop.adaptive.session import adaptive_plan, row_at_level

        plan = adaptive_plan(protocol)
        assert plan is not None
        row = row_at_level(plan, row, level)
    return row, level, gaze_deg


def _mode_and_text(args: argparse.Namespace, protocol: Protocol, row: dict) -> tuple[str, str | None]:
    """The rendering mode and, for ``--phase response``, the participant's response text."""
    from psyop.stimulus import interval_mode

    if args.phase in SCREEN_PHASES:
        return args.mode or "conventional", _screen_text(args, protocol)
    if args.phase == "response":
        from psyop.session.plan import compile_plan

        response = compile_plan(protocol, tracker_ipd_m=ipd_arg_m(args.ipd_mm)).response
        return args.mode or response.phase.mode, response.participant_text
    return args.mode or interval_mode(protocol, row, args.interval), None


def _screen_text(args: argparse.Namespace, protocol: Protocol) -> str:
    """The text of screen ``--screen`` of ``--phase`` (a break as after its first ``every_trials`` trials, else
    after the first block, of the schedule of ``--seed``)."""
    from psyop.schedule import compile_schedule
    from psyop.session.screens import screens_of_kind

    section = protocol.session
    if section is None:
        raise UserError(f"--phase {args.phase}: the protocol has no session: section; add one "
                        "(docs/session_screens.md)", args.protocol)
    schedule = compile_schedule(protocol, args.seed, participant_index=args.participant_index)
    total = len(schedule)
    every = section.breaks.every_trials if section.breaks is not None else None
    done = min(every, total) if every else int((schedule["block"] == schedule["block"].iloc[0]).sum())
    screens = screens_of_kind(section, args.phase, done=done, total=total)
    if not screens:
        raise UserError(f"--phase {args.phase}: the protocol's session: section has no such screen; add one "
                        "(docs/session_screens.md)", args.protocol)
    if not 0 <= args.screen < len(screens):
        raise UserError(f"--screen must be in 0..{len(screens) - 1} for --phase {args.phase}, got {args.screen}")
    return screens[args.screen].text


@dataclass(frozen=True)
class _View:
    """The rendered eye's geometry and camera for one frame."""

    eye: str
    mode: str
    ipd_m: float
    centre_m: np.ndarray
    fixation_m: np.ndarray
    nc_m: float
    camera: EyeCamera
    display: DisplayProfile
    eye_model: EyeModel


def _view(args: argparse.Namespace, protocol: Protocol, row: dict, mode: str, az: float, el: float) -> _View:
    from psyop.optics.camera import make_eye_camera
    from psyop.protocol import resolve_display_profile, resolve_eye_model
    from psyop.optics.nodal import eye_centre_m
    from psyop.protocol.display import protocol_ipd_m, rendering_nc_rule
    from psyop.rendering.builders import direction_from_angles
    from psyop.schedule import interval_values

    eye = args.eye or (protocol.eyes if protocol.eyes in ("right", "left") else "right")
    display = resolve_display_profile(protocol.display)
    eye_model = resolve_eye_model(protocol.display)
    ipd_m = protocol_ipd_m(protocol.display.ipd, ipd_arg_m(args.ipd_mm))
    centre = eye_centre_m(eye, ipd_m)
    fixation = centre + direction_from_angles(az, el) * args.fixation_m
    nc_rule = rendering_nc_rule(protocol.display)
    nc_m = eye_model.nc_m if nc_rule is None else nc_rule.nc_m_for(eye_model.nc_m, interval_values(row, args.interval))
    camera = make_eye_camera(display, eye, fixation, ipd_m, nc_m, mode)
    if args.crop:
        from psyop.rendering.camera_math import crop_camera

        x0, y0, w, h = _parse_crop(args.crop, camera.width_px, camera.height_px)
        camera = crop_camera(camera, x0, y0, w, h)
    return _View(eye, mode, ipd_m, centre, fixation, nc_m, camera, display, eye_model)


def _scene(args: argparse.Namespace, protocol: Protocol, protocol_path: Path, row: dict, view: _View,
           response_text: str | None, mesh_files: MeshFiles) -> Scene:
    from psyop.stimulus import build_scene
    from psyop.stimulus.meshes import SessionMeshes

    if args.phase == "response" or args.phase in SCREEN_PHASES:
        from psyop.protocol.kinds import kind_of
        from psyop.rendering.text import TextDoesNotFit, TextImages, display_views
        from psyop.session.plan import compile_plan
        from psyop.session.text_fit import panel_offsets_tan
        from psyop.stimulus import blank_scene, scene_origin_m, text_scene

        if response_text is None:
            return blank_scene()
        # laid out as the session lays it out on this display (docs/rendering.md, "Legible text")
        plan = compile_plan(protocol, tracker_ipd_m=view.ipd_m)
        texts = TextImages(views=display_views(view.display, panel_offsets_tan(plan)))
        keep = args.phase in SCREEN_PHASES or kind_of(protocol.response).response_text(protocol.response) is not None
        from psyop.session.screens import instruction_picture

        picture = instruction_picture(protocol.session, args.screen, protocol_path.parent) \
            if args.phase == "instructions" else None  # an instruction page's image above its text
        try:
            image = texts.image(response_text, keep_lines=keep) if picture is None else \
                texts.page(response_text, picture)
        except TextDoesNotFit as error:
            raise UserError(f"--phase {args.phase}: {error}") from None
        return text_scene(image, scene_origin_m(protocol, view.centre_m))
    return build_scene(protocol, row, args.time_s, view.centre_m, interval=args.interval, base_dir=protocol_path.parent,
                       meshes=SessionMeshes(protocol_path.parent, mesh_files))


def _sidecar(args: argparse.Namespace, protocol: Protocol, protocol_path: Path, level: float | None,
             response_text: str | None, az: float, el: float, view: _View, scene: Scene) -> dict:
    """What the frame is (the PNG's JSON sidecar)."""
    import numpy as np

    display, eye_model, camera = view.display, view.eye_model, view.camera
    return {
        "protocol": str(protocol_path), "protocol_sha256": protocol.source_sha256, "seed": args.seed,
        "trial": args.trial, "phase": args.phase, "interval": args.interval, "time_s": args.time_s,
        "screen": args.screen if args.phase in SCREEN_PHASES else None,
        "adaptive_level": level,
        "response_text": response_text,
        "eye": view.eye, "mode": view.mode, "gaze_deg": [az, el], "fixation_m": view.fixation_m.tolist(),
        "camera_valid": bool(camera.valid),
        "centre_of_projection_m": np.asarray(camera.centre_of_projection_m).tolist(),
        "eye_centre_m": view.centre_m.tolist(), "ipd_m": view.ipd_m,
        "frustum_tangents": frustum_tangents(camera.pixel_to_ray),
        "resolution_px": [camera.width_px, camera.height_px],
        "display_profile": display.name, "image_distance_m": None if math.isinf(display.d_m) else display.d_m,
        "eye_model": {"name": eye_model.name, "nc_m": eye_model.nc_m}, "rendered_nc_m": view.nc_m,
        "crop_px": args.crop, "antialiasing": args.antialiasing, "primitives": [p.name for p in scene.primitives],
    }


def run(args: argparse.Namespace) -> int:
    from psyop.atomic import write_atomic
    from psyop.mesh.load import MeshFiles
    from psyop.protocol import load_protocol
    from psyop.rendering import Renderer, RenderSettings

    protocol_path = Path(args.protocol)
    mesh_files = MeshFiles(protocol_path.parent)  # each model read once: validation and the scene
    protocol = load_protocol(protocol_path, meshes=mesh_files)
    row, level, (az, el) = _checked_trial(args, protocol)
    mode, response_text = _mode_and_text(args, protocol, row)
    view = _view(args, protocol, row, mode, az, el)
    scene = _scene(args, protocol, protocol_path, row, view, response_text, mesh_files)
    with Renderer(scene, RenderSettings(antialiasing=args.antialiasing, reuse_tolerance_px=None)) as renderer:
        renderer.render(view.camera)
        image = renderer.image_uint8(view.eye)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_png(out, image)
    sidecar = _sidecar(args, protocol, protocol_path, level, response_text, az, el, view, scene)
    write_atomic(Path(str(out) + ".json"), json.dumps(sidecar, indent=2) + "\n")
    camera = view.camera
    print(f"wrote {out} ({camera.width_px}x{camera.height_px}, {view.eye} eye, {mode}) and {out}.json")
    return 0
