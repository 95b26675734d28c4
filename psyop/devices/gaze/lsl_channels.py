"""Which LSL channel carries what: channel maps by label, built in for Pupil Capture's relay and
Neon, or read from a JSON file for any other tracker.

A map names, for each *role* psyop reads (:data:`ROLES`), the channel label (and, where a stream
labels both eyes' channels alike, as Neon does, the ``eye`` of its ``desc/channels/channel``
entry). Where the fixation comes from is the map's ``fixation``:

- ``pupil_world_mm``: ``gaze_point_{x,y,z}`` in Pupil's world-camera frame (x right, y down,
  z forward, mm), as Pupil Capture's LSL relay sends ``gaze_point_3d_*``;
- ``head_m``: ``gaze_point_{x,y,z}`` already in psyop's head space (x right, y up, -z forward, m);
- ``scene_px``: ``scene_{x,y}_px``, a pixel of the scene camera (origin top left), turned into a
  direction through a pinhole with the map's ``scene`` size and field of view, at
  ``scene.distance_m`` (Neon sends only this: its fixation distance is not measured, and the
  pinhole ignores the lens distortion; session.json records that the fixation came this way).

A file map is JSON: ``{"name": ..., "fixation": ..., "roles": {ROLE: LABEL or {"label": L, "eye":
E}}, "scene": {"width_px": ..., "height_px": ..., "hfov_deg": ..., "vfov_deg": ..., "distance_m":
...}}``; every error names the file and the fix (exit code 2).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from psyop.errors import UserError

#: every role a map may fill (eye roles are per ``left``/``right``)
EYE_ROLES: tuple[str, ...] = (
    *(f"eye_centre_{{eye}}_{a}_mm" for a in "xyz"), *(f"gaze_normal_{{eye}}_{a}" for a in "xyz"),
    "pupil_diameter_{eye}_mm", "pupil_diameter_{eye}_px",
)
ROLES: tuple[str, ...] = (
    "confidence", *(f"gaze_point_{a}" for a in "xyz"), "norm_pos_x", "norm_pos_y", "scene_x_px", "scene_y_px",
    *(r.format(eye=eye) for eye in ("left", "right") for r in EYE_ROLES),
)
FIXATION_KINDS = ("pupil_world_mm", "head_m", "scene_px")
#: the roles each fixation kind needs
FIXATION_ROLES: dict[str, tuple[str, ...]] = {
    "pupil_world_mm": ("gaze_point_x", "gaze_point_y", "gaze_point_z"),
    "head_m": ("gaze_point_x", "gaze_point_y", "gaze_point_z"),
    "scene_px": ("scene_x_px", "scene_y_px"),
}


@dataclass(frozen=True)
class ChannelRef:
    """A channel by its ``label`` and, where labels repeat per eye, its ``eye`` (``left``/``right``)."""

    label: str
    eye: str | None = None


@dataclass(frozen=True)
class SceneCamera:
    """A pinhole for ``scene_px`` maps: image size, full fields of view and the assumed distance."""

    width_px: float
    height_px: float
    hfov_deg: float
    vfov_deg: float
    distance_m: float = 1.0

    def direction_world(self, x_px: float, y_px: float) -> tuple[float, float, float]:
        """The unit direction (world-camera frame: x right, y down, z forward) through a pixel."""
        fx = 0.5 * self.width_px / math.tan(math.radians(0.5 * self.hfov_deg))
        fy = 0.5 * self.height_px / math.tan(math.radians(0.5 * self.vfov_deg))
        x, y = (x_px - 0.5 * self.width_px) / fx, (y_px - 0.5 * self.height_px) / fy
        norm = math.sqrt(x * x + y * y + 1.0)
        return (x / norm, y / norm, 1.0 / norm)


@dataclass(frozen=True)
class ChannelMap:
    """Roles -> channels (module docstring). ``confidence`` missing: a finite sample has confidence 1
    (Neon sends none; recorded in the tracker stats)."""

    name: str
    fixation: str
    roles: Mapping[str, ChannelRef]
    scene: SceneCamera | None = None
    note: str = ""

    def required(self) -> tuple[str, ...]:
        return FIXATION_ROLES[self.fixation]

    def resolve(self, channels: Sequence[tuple[str, str | None]], where: str) -> dict[str, int]:
        """Channel index of every role this map fills, from the stream's (label, eye) channels.

        A role whose channel the stream lacks is left out; a missing fixation role is a UserError
        naming the stream's labels."""
        index: dict[str, int] = {}
        for role, ref in self.roles.items():
            hits = [i for i, (label, eye) in enumerate(channels)
                    if label == ref.label and (ref.eye is None or (eye or "").lower() == ref.eye)]
            if hits:
                index[role] = hits[0]
        missing = [r for r in self.required() if r not in index]
        if missing:
            labels = ", ".join(label + (f"[{eye}]" if eye else "") for label, eye in channels) or "none"
            raise UserError(f"LSL stream {where}: channel map {self.name!r} needs channels for {missing} "
                            f"({', '.join(self.roles[r].label for r in missing)}); the stream has: {labels}. "
                            "Give a channel map file: --tracker 'lsl:NAME@MAP.json' (docs/sessions.md)", "--tracker")
        return index


def _pupil_relay_map() -> ChannelMap:
    roles = {"confidence": ChannelRef("confidence"), "norm_pos_x": ChannelRef("norm_pos_x"),
             "norm_pos_y": ChannelRef("norm_pos_y"),
             **{f"gaze_point_{a}": ChannelRef(f"gaze_point_3d_{a}") for a in "xyz"}}
    for pupil_eye, eye in ((0, "right"), (1, "left")):  # Pupil's eye 0 is the right eye
        roles.update({f"eye_centre_{eye}_{a}_mm": ChannelRef(f"eye_center{pupil_eye}_3d_{a}") for a in "xyz"})
        roles.update({f"gaze_normal_{eye}_{a}": ChannelRef(f"gaze_normal{pupil_eye}_{a}") for a in "xyz"})
        roles[f"pupil_diameter_{eye}_px"] = ChannelRef(f"diameter{pupil_eye}_2d")
        roles[f"pupil_diameter_{eye}_mm"] = ChannelRef(f"diameter{pupil_eye}_3d")
    return ChannelMap("pupil_capture", "pupil_world_mm", roles,
                      note="Pupil Capture LSL relay (labstreaminglayer/App-PupilLabs), 22 channels")


def _neon_map() -> ChannelMap:
    roles = {"scene_x_px": ChannelRef("x"), "scene_y_px": ChannelRef("y")}
    for eye in ("left", "right"):
        roles[f"pupil_diameter_{eye}_mm"] = ChannelRef("PupilDiameter", eye)
        roles.update({f"eye_centre_{eye}_{a}_mm": ChannelRef(f"EyeballCenter{a.upper()}", eye) for a in "xyz"})
        roles.update({f"gaze_normal_{eye}_{a}": ChannelRef(f"OpticalAxis{a.upper()}", eye) for a in "xyz"})
    # Neon's scene camera: 1600 x 1200 px, 103 x 77 deg (docs.pupil-labs.com, Neon data streams)
    return ChannelMap("neon", "scene_px", roles, SceneCamera(1600.0, 1200.0, 103.0, 77.0, 1.0),
                      note="Neon Companion LSL outlet '<device>_Neon Gaze': fixation direction from the scene-camera "
                           "pixel through a 103 x 77 deg pinhole (no distortion model) at an assumed 1 m")


BUILT_IN: dict[str, ChannelMap] = {m.name: m for m in (_pupil_relay_map(), _neon_map())}


def detect_map(channels: Sequence[tuple[str, str | None]]) -> ChannelMap | None:
    """The built-in map whose fixation channels the stream has (None: no built-in fits)."""
    labels = {label for label, _ in channels}
    for candidate in BUILT_IN.values():
        if all(candidate.roles[r].label in labels for r in candidate.required()):
            return candidate
    return None


def load_map(spec: str) -> ChannelMap:
    """A built-in map by name, or a JSON map file (module docstring)."""
    if spec in BUILT_IN:
        return BUILT_IN[spec]
    path = Path(spec)
    if not path.is_file():
        raise UserError(f"channel map {spec!r} is neither a built-in ({', '.join(BUILT_IN)}) nor a JSON file",
                        "--tracker")
    try:
        raw = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"cannot read the channel map: {exc}", str(path)) from exc
    except json.JSONDecodeError as exc:
        raise UserError(f"channel map is not valid JSON: {exc.msg}", f"{path}:{exc.lineno}:{exc.colno}") from exc
    return parse_map(raw, str(path))


def parse_map(raw: object, where: str) -> ChannelMap:
    """A :class:`ChannelMap` from its JSON form; every mistake is one UserError naming ``where``.

    Examples
    --------
    >>> m = parse_map({"fixation": "head_m", "roles": {"gaze_point_x": "gx", "gaze_point_y": "gy",
    ...                "gaze_point_z": "gz", "confidence": {"label": "q"}}}, "map.json")
    >>> m.fixation, m.roles["confidence"].label
    ('head_m', 'q')
    """
    if not isinstance(raw, dict):
        raise UserError("a channel map is a JSON object with 'fixation' and 'roles'", where)
    unknown = sorted(set(raw) - {"name", "fixation", "roles", "scene"})
    if unknown:
        raise UserError(f"channel map: unknown keys {unknown}; use name, fixation, roles, scene", where)
    fixation = raw.get("fixation")
    if fixation not in FIXATION_KINDS:
        raise UserError(f"channel map: 'fixation' must be one of {list(FIXATION_KINDS)}, got {fixation!r}", where)
    roles_raw = raw.get("roles")
    if not isinstance(roles_raw, dict):
        raise UserError("channel map: 'roles' must map role names to channel labels", where)
    roles: dict[str, ChannelRef] = {}
    for role, ref in roles_raw.items():
        if role not in ROLES:
            raise UserError(f"channel map: unknown role {role!r}; roles are {', '.join(ROLES)}", where)
        if isinstance(ref, str) and ref:
            roles[role] = ChannelRef(ref)
        elif isinstance(ref, dict) and isinstance(ref.get("label"), str) and set(ref) <= {"label", "eye"} \
                and ref.get("eye") in (None, "left", "right"):
            roles[role] = ChannelRef(ref["label"], ref.get("eye"))
        else:
            raise UserError(f"channel map: role {role!r} needs a label or {{\"label\": ..., \"eye\": "
                            "\"left\"|\"right\"}}", where)
    missing = [r for r in FIXATION_ROLES[fixation] if r not in roles]
    if missing:
        raise UserError(f"channel map: fixation {fixation!r} needs the roles {missing}", where)
    scene = None
    if fixation == "scene_px":
        s = raw.get("scene")
        keys = ("width_px", "height_px", "hfov_deg", "vfov_deg")
        if not isinstance(s, dict) or any(not isinstance(s.get(k), (int, float)) or s[k] <= 0 for k in keys):
            raise UserError(f"channel map: fixation 'scene_px' needs 'scene' with positive {list(keys)} "
                            "(and optionally distance_m)", where)
        if not all(0 < s[k] < 180 for k in ("hfov_deg", "vfov_deg")):
            raise UserError("channel map: scene fields of view must be between 0 and 180 deg", where)
        scene = SceneCamera(float(s["width_px"]), float(s["height_px"]), float(s["hfov_deg"]), float(s["vfov_deg"]),
                            float(s.get("distance_m", 1.0)))
    return ChannelMap(str(raw.get("name", where)), fixation, roles, scene, note=f"channel map file {where}")

