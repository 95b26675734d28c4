"""A session's gaze samples for export, and where each eye's line of sight meets its display image.

Source: the raw gaze stream file (:data:`RAW_GAZE_FILE`, every tracker sample, before psyop's
per-trial drift correction) when the session has one with samples; otherwise the frame log's gaze samples (``frames.parquet``: the sample each rendered
frame used, after drift correction, so at most one per frame, held repeats dropped). :func:`session_gaze` says which one
it read; the BIDS sidecar states it.

The tracker reports a fixation point in head space (x right, y up, -z forward, metres, from the
mid-point between the eyes; psyop.session.gaze.sample). Each eye's display shows a virtual image
whose extent is given by tangents seen from that eye's centre of rotation C
(psyop.optics.display). :func:`gaze_on_image_px` intersects the line from C through the fixation
point with that image: pixel x to the right from the left edge, y down from the top edge
(docs/architecture.md's pixel convention), the same for any image distance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import numpy as np
import pandas as pd

from psyop import datacontract as dc
from psyop.errors import UserError
from psyop.optics.display import DisplayProfile
from psyop.optics.nodal import eye_centre_m
from psyop.records import JsonMapping

#: The raw gaze stream of a session (every tracker sample), finalised beside trials.parquet.
RAW_GAZE_FILE = "gaze.parquet"
#: Columns the raw gaze stream must have (the frame log's gaze column names).
RAW_GAZE_COLUMNS: tuple[str, ...] = (dc.GAZE_SAMPLE_T_S, dc.FIXATION_X_M, dc.FIXATION_Y_M, dc.FIXATION_Z_M,
                                     dc.GAZE_VALID)
#: Optional per-eye pupil diameter columns of the raw stream (``{eye}`` is left or right).
PUPIL_COLUMN = "pupil_diameter_{eye}_mm"

FRAME_LOG = "frame log"
RAW_STREAM = "raw gaze stream"


@dataclass(frozen=True)
class SessionGaze:
    """Gaze samples of one session, oldest first, one row per distinct sample time.

    ``samples`` has ``gaze_sample_t_s``, ``fixation_{x,y,z}_m``, ``gaze_valid``,
    ``gaze_confidence`` (NaN where the source has none), ``trial`` (the frame log's, or -1 for
    the raw stream) and, from a raw stream only, ``run`` (when it has one: which psyop run
    recorded the sample) and ``pupil_diameter_{eye}_mm``.
    """

    source: str  # FRAME_LOG or RAW_STREAM
    file: str
    samples: pd.DataFrame


def session_gaze(directory: Path) -> SessionGaze:
    """The session's gaze samples: the raw stream if it holds any, else the frame log's.

    Examples
    --------
    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> pd.DataFrame({"trial": [0, 0], "frame": [0, 1], "gaze_sample_t_s": [0.5, 0.5], "fixation_x_m": [0.0, 0.0],
    ...               "fixation_y_m": [0.0, 0.0], "fixation_z_m": [-1.0, -1.0], "gaze_confidence": [0.9, 0.9],
    ...               "gaze_valid": [True, True]}).to_parquet(d / "frames.parquet")
    >>> gaze = session_gaze(d)
    >>> gaze.source, len(gaze.samples)
    ('frame log', 1)
    """
    directory = Path(directory)
    raw = directory / RAW_GAZE_FILE
    table = pd.read_parquet(raw) if raw.is_file() else None
    if table is not None and len(table) >= 2:  # an (almost) empty raw stream: the frame log's samples
        missing = [c for c in RAW_GAZE_COLUMNS if c not in table]
        if missing:
            raise UserError(f"raw gaze stream lacks column(s) {missing}; expected {list(RAW_GAZE_COLUMNS)}", str(raw))
        table = table.copy()
        if dc.GAZE_CONFIDENCE not in table:
            table[dc.GAZE_CONFIDENCE] = np.nan
        table["trial"] = table["trial"] if "trial" in table else -1
        source, name = RAW_STREAM, RAW_GAZE_FILE
    else:
        path = directory / dc.FRAMES_FILE
        if not path.is_file():
            raise UserError("no gaze samples: neither a raw gaze stream nor frames.parquet", str(directory))
        table = pd.read_parquet(path)
        source, name = FRAME_LOG, dc.FRAMES_FILE
    table = table[np.isfinite(pd.to_numeric(table[dc.GAZE_SAMPLE_T_S], errors="coerce"))]
    table = table.sort_values(dc.GAZE_SAMPLE_T_S, kind="stable")
    table = table.drop_duplicates(subset=dc.GAZE_SAMPLE_T_S, keep="first").reset_index(drop=True)
    keep = [*RAW_GAZE_COLUMNS, dc.GAZE_CONFIDENCE, "trial", "run",
            *(c for c in table.columns if c.startswith("pupil_diameter_"))]
    return SessionGaze(source, name, table[[c for c in keep if c in table]])


def display_from_metadata(meta: JsonMapping, where: str) -> DisplayProfile:
    """The session's display profile as session.json records it (``display``)."""
    raw = meta.get("display")
    if not isinstance(raw, Mapping):
        raise UserError("session.json has no display profile (\"display\"): cannot place gaze on the image", where)
    fields = {k: raw[k] for k in ("name", "width_px", "height_px", "refresh_hz", "tan_left", "tan_right",
                                  "tan_bottom", "tan_top") if k in raw}
    d_m = raw.get("d_m", "inf")
    left = raw.get("left_tangents")  # the left eye's own frustum (per-eye FOV), else mirrored
    try:
        return DisplayProfile(**fields, d_m=math.inf if d_m in (None, "inf") else float(d_m),
                              left_tangents=None if left is None else tuple(left))
    except (TypeError, ValueError) as exc:
        raise UserError(f"session.json's display profile is not usable: {exc}", where) from exc


def gaze_on_image_px(fixation_m: np.ndarray, display: DisplayProfile, eye: str, ipd_m: float) -> np.ndarray:
    """(n, 2) pixel coordinates where the line from ``eye``'s centre of rotation through each
    fixation point meets that eye's image; NaN where the point is not in front of the eye.

    Examples
    --------
    >>> from psyop.optics.display import VIVE_PRO
    >>> straight_ahead = np.array([[0.0315, 0.0, -1.0]])
    >>> gaze_on_image_px(straight_ahead, VIVE_PRO, "right", 0.063)
    array([[720., 800.]])
    """
    points = np.asarray(fixation_m, dtype=np.float64).reshape(-1, 3) - eye_centre_m(eye, ipd_m)
    left, right, bottom, top = display.frustum_tangents(eye)
    forward = -points[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        tan_x = np.where(forward > 0, points[:, 0] / forward, np.nan)
        tan_y = np.where(forward > 0, points[:, 1] / forward, np.nan)
    x_px = (tan_x - left) / (right - left) * display.width_px
    y_px = (top - tan_y) / (top - bottom) * display.height_px
    return np.column_stack([x_px, y_px])


@dataclass(frozen=True)
class ImageGeometry:
    """BIDS ``StimulusPresentation`` of one eye's image: distance and size in metres, resolution.

    An image at optical infinity (``d_m`` inf, the paper's headset) has no physical distance or
    size; it is described as the flat screen at :data:`EQUIVALENT_DISTANCE_M` that subtends the
    same angles (``equivalent`` true), which gives the same visual angles for every pixel."""

    distance_m: float
    width_m: float
    height_m: float
    width_px: int
    height_px: int
    equivalent: bool


EQUIVALENT_DISTANCE_M = 1.0


def image_geometry(display: DisplayProfile, eye: str) -> ImageGeometry:
    """The eye's image as BIDS describes a screen (see :class:`ImageGeometry`)."""
    left, right, bottom, top = display.frustum_tangents(eye)
    equivalent = not math.isfinite(display.d_m)
    d_m = EQUIVALENT_DISTANCE_M if equivalent else float(display.d_m)
    return ImageGeometry(d_m, d_m * (right - left), d_m * (top - bottom), display.width_px, display.height_px,
                         equivalent)


_TANGENT_KEYS = ("tan_left", "tan_right", "tan_bottom", "tan_top")


@dataclass(frozen=True)
class RunDisplay:
    """Each eye's display image in one psyop run, as the export describes it (``StimulusPresentation``, gaze
    pixel coordinates), and a note saying where it came from.

    From the run's ``display_used`` (session.json ``runs``; psyop.run.assembly.display_used) when the run
    measured its display: a headset's swapchain size, field of view and measured rate per eye, or a window's
    presented image size and measured flip rate. Otherwise (headless, or a session recorded before psyop
    recorded ``display_used``) the protocol's display profile, and the note says so."""

    eyes: Mapping[str, DisplayProfile]
    measured: bool
    note: str


def run_display(meta: JsonMapping, run: int, profile: DisplayProfile, where: str) -> RunDisplay:
    """The display of run ``run`` (the trials' ``run``) of the session whose session.json is ``meta``."""
    runs = meta.get("runs")
    entry = next((r for r in (runs if isinstance(runs, list) else []) if isinstance(r, Mapping) and r.get("run") == run),
                 {})
    used = entry.get("display_used")
    if not isinstance(used, Mapping) or used.get("measured") is not True:
        why = ("the run recorded no display_used" if not isinstance(used, Mapping) else "no screen (headless)"
               if used.get("display") == "headless" else "the run showed no frame")
        note = (f"Screen geometry and refresh rate are the protocol's display profile {profile.name!r} ({why}): "
                "nothing was measured.")
        if not isinstance(used, Mapping) and str(entry.get("display_mode", "")).startswith(("openxr", "window")):
            note += (f" This {entry.get('display_mode')} run was not finalised by psyop run (killed, then recovered), "
                     "so the display it really used may differ from the profile; for a headset, frames.parquet's "
                     "view_<eye>_tan_* columns hold the runtime's field of view per frame.")
        return RunDisplay({eye: profile for eye in ("left", "right")}, False, note)
    eyes_used = used.get("eyes")
    if not isinstance(eyes_used, Mapping) or not eyes_used:
        raise UserError(f"session.json's display_used of run {run} has no eyes: cannot place gaze on the image", where)
    rate = used.get("refresh_hz")
    rate_hz = float(rate) if isinstance(rate, (int, float)) and not isinstance(rate, bool) else math.nan
    measured_rate = math.isfinite(rate_hz) and rate_hz > 0
    kind = str(used.get("display"))
    name = f"{used.get('system') or used.get('runtime')} (OpenXR)" if kind == "openxr" else f"{profile.name} (window)"
    eyes = {}
    for eye, entry in eyes_used.items():
        try:
            left, right, bottom, top = (float(entry[k]) for k in _TANGENT_KEYS)
            eyes[str(eye)] = DisplayProfile(
                name=name, width_px=int(entry["width_px"]), height_px=int(entry["height_px"]),
                refresh_hz=rate_hz if measured_rate else float(profile.refresh_hz),
                tan_left=left, tan_right=right, tan_bottom=bottom, tan_top=top,
                d_m=math.inf if kind == "openxr" else profile.d_m, left_tangents=(left, right, bottom, top))
        except (KeyError, TypeError, ValueError) as exc:
            raise UserError(f"session.json's display_used of run {run}, {eye} eye, is not usable: {exc}", where) from exc
    return RunDisplay(eyes, True, _measured_note(used, kind, profile, measured_rate))


def _measured_note(used: JsonMapping, kind: str, profile: DisplayProfile, measured_rate: bool) -> str:
    if kind == "openxr":
        note = (f"Screen geometry is what the OpenXR runtime {used.get('runtime')!r} ({used.get('system')!r}) used: "
                "each eye's swapchain size and its field of view (xrLocateViews), not the protocol's profile "
                f"{profile.name!r}. ")
        changed = used.get("fov_frames_changed")
        if isinstance(changed, int) and changed:
            note += (f"The runtime changed the field of view in {changed} frames (largest tangent change "
                     f"{used.get('fov_max_change_tan')}); the first frame's is given. ")
        canted = [eye for eye, e in (used.get("eyes") or {}).items() if isinstance(e, Mapping)
                  and e.get("orientation_wxyz") not in (None, [1.0, 0.0, 0.0, 0.0])]
        if canted:
            note += (f"The runtime's views of {', '.join(canted)} are canted (session.json display_used "
                     "orientation_wxyz); pixel coordinates are on an uncanted image. ")
        rate_source = "the runtime's predicted display times (1 / median interval)"
    else:
        note = (f"Screen resolution is each eye's image as the window presented it (the profile {profile.name!r}'s "
                "field of view, rendered at the window scale). ")
        rate_source = "the window's flip timestamps (1 / median interval)"
    if measured_rate:
        return note + f"ScreenRefreshRate is measured from {rate_source}."
    return note + (f"ScreenRefreshRate is the profile's {profile.refresh_hz:g} Hz: too few frames to measure it from "
                   f"{rate_source}.")
