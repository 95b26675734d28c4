"""Render every audited frame of a protocol and check what the participant would see.

The frames come from the session plan (``psyop.session.plan.compile_plan``): its interval
phases and the blank phases that show primitives, with their modes, durations and ``show:`` lists, its eye rig (eyes, ipd, eye model,
cameras) and display, so the audit sees what a session would draw.

Checks (each failure is one line naming the primitive, its scene item and the frame):

* **never visible**: a rendered primitive whose visible area is below :data:`MIN_VISIBLE_SAMPLES`
  edge samples in every audited frame (a declared stimulus the participant never sees);
* **shows although hidden**: a primitive that exact geometry says is wholly covered by another
  in this frame (:mod:`psyop.audit.occlusion`) but has visible area in the rendered frame;
* **identical intervals**: the two intervals of a trial differ in their values (level, mode)
  but render bit-identically at every audited gaze of some eye.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from psyop.audit.crops import SheetCrop, sheet_crop
from psyop.audit.frames import AuditFrame, fixation_point, representative_rows
from psyop.audit.masks import FrameMeasurer
from psyop.audit.luminance import LuminanceCheck, luminance_checks
from psyop.audit.meshes import MeshCheck
from psyop.audit.occlusion import hidden_by
from psyop.errors import UserError
from psyop.optics.ranges import DEFAULT_IPD_M, IPD_M
from psyop.records import TrialRow

if TYPE_CHECKING:
    import moderngl

    from psyop.optics.camera import EyeCamera
    from psyop.optics.display import DisplayProfile
    from psyop.protocol.model import Protocol
    from psyop.rendering.scene import Scene
    from psyop.session.phases import PhaseSpec
    from psyop.session.plan import SessionPlan
    from psyop.mesh.load import MeshFiles

# Visible means covering at least half of one of the S x S samples of an edge pixel; exact
# occlusion leaves a hidden primitive's mask at exactly 0.
MIN_VISIBLE_SAMPLES = 0.5


@dataclass(frozen=True)
class AuditSettings:
    """``scale``: the display's pixel counts are multiplied by it (frustum unchanged);
    ``gazes``: gazes per (condition, interval, eye); ``samples_per_axis``: the adaptive
    sampler's S (S x S rays in edge pixels; the session uses 32); ``ipd_m`` when the protocol
    takes the ipd from the tracker; ``seed``: the schedule seed that picks each condition's trial."""

    scale: float = 0.125
    gazes: int = 4
    samples_per_axis: int = 16
    ipd_m: float = DEFAULT_IPD_M  # the sessions' default, as ``psyop audit --ipd-mm``
    seed: int = 0
    #: an adaptive factor's levels to audit (each condition at each); empty: the range's min, start and max
    levels: tuple[float, ...] = ()
    #: compare every mesh item's silhouette with exact ray-triangle intersection (numpy: ~2 s of CPU per
    #: frame for a room that fills it); off, each mesh gets a note that it was not compared
    mesh_check: bool = True
    #: render every frame again in the contact sheet's crop (psyop.audit.crops): ``psyop audit --sheet`` turns it on
    sheet_crop: bool = False

    def __post_init__(self) -> None:
        if not (math.isfinite(self.scale) and 0.01 <= self.scale <= 1.0):
            raise UserError(f"--scale must be in [0.01, 1], got {self.scale}")
        if not 2 <= self.samples_per_axis <= 32:
            raise UserError(f"--samples must be in 2..32, got {self.samples_per_axis}")
        if not 1 <= self.gazes <= 64:
            raise UserError(f"--gazes must be in 1..64, got {self.gazes}")
        if not IPD_M.contains(self.ipd_m):
            raise UserError(f"--ipd-mm must be in {IPD_M.describe(1000.0, 'mm')}, got {self.ipd_m * 1000:g}")


@dataclass(frozen=True)
class FrameRecord:
    """What one audited frame showed: visible area per primitive in display pixels (full
    resolution: audit pixels / scale^2) and which primitives geometry says are hidden."""

    frame: AuditFrame
    names: tuple[str, ...]
    items: tuple[str, ...]
    visible_px2: tuple[float, ...]
    hidden_by: dict[int, int]
    image: np.ndarray = field(compare=False, repr=False)
    centre_of_projection_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: pixels of this (audit-scale) frame per metre of centre-of-projection shift, for the nearest
    #: finite primitive: a shift ``s`` moves no edge by more than about ``s * px_per_m_shift``
    px_per_m_shift: float = 0.0
    #: each mesh item's rendered silhouette against exact ray-triangle intersection, display pixels
    meshes: tuple[MeshCheck, ...] = ()
    #: on a calibrated display: each luminance primitive's intended and achieved luminance and contrast
    #: (psyop.audit.luminance)
    luminance: tuple[LuminanceCheck, ...] = ()
    #: the frame in the contact sheet's crop (:attr:`AuditReport.sheet_crop`), when the audit made one
    sheet_image: np.ndarray | None = field(default=None, compare=False, repr=False)


@dataclass(frozen=True)
class AuditReport:
    protocol_name: str
    settings: AuditSettings
    records: tuple[FrameRecord, ...]
    failures: tuple[str, ...]
    notes: tuple[str, ...]
    #: the window every record's ``sheet_image`` shows (None: the sheet shows whole frames)
    sheet_crop: SheetCrop | None = None

    @property
    def passed(self) -> bool:
        return not self.failures


def item_of(name: str, item_ids: list[str]) -> str:
    """The scene item a primitive came from: its name is the item's id or ``<id>_...``."""
    matches = [i for i in item_ids if name == i or name.startswith(i + "_")]
    return max(matches, key=len) if matches else name


def _point3(point: np.ndarray) -> tuple[float, float, float]:
    """A 3-vector as a tuple of Python floats."""
    x, y, z = (float(c) for c in point)
    return x, y, z


def _fixation_prefix(protocol: Protocol) -> str | None:
    from psyop.protocol import scene as ps

    for item in protocol.scene:
        if isinstance(item, ps.FixationTarget):
            return str(item.id)
    return None


def iter_frames(plan: SessionPlan, settings: AuditSettings) -> Iterator[tuple[AuditFrame, PhaseSpec]]:
    """Every audited frame and its plan phase, in order: condition, phase, eye, gaze."""
    from psyop.schedule import compile_schedule

    schedule = compile_schedule(plan.protocol, settings.seed, participant_index=0)  # block order: irrelevant here
    phases = [(i, phase) for i, phase in enumerate(plan.phases)
              if phase.show == "stimulus" or (phase.show == "blank" and phase.primitives)]
    rows = representative_rows(schedule)
    if plan.adaptive is not None:  # the level is chosen at run time: audit each condition at a few levels
        from psyop.adaptive.session import preview_levels, row_at_level

        levels = preview_levels(plan.protocol, settings.levels)
        rows = [dict(row_at_level(plan.adaptive, row, level),
                     condition=f"{row['condition']}|{plan.adaptive.factor}={level:g}")
                for row in rows for level in levels]
    elif settings.levels:
        from psyop.adaptive.session import preview_levels

        preview_levels(plan.protocol, settings.levels)  # the error: no adaptive factor to set
    for row in rows:
        for index, phase in phases:
            mode = plan.mode_for(phase, row)
            for eye in plan.eyes:
                for k in range(settings.gazes):
                    yield AuditFrame(str(row["condition"]), int(row["trial"]), row, phase.name, index,
                                     max(1, phase.interval), mode, eye, k,
                                     float(phase.duration_s) * k / settings.gazes), phase


def run_audit(protocol: Protocol, settings: AuditSettings, ctx: moderngl.Context | None = None, base_dir: Path | None = None,
              progress: Callable[[int, int], None] | None = None, mesh_files: MeshFiles | None = None) -> AuditReport:
    """Render and check every audited frame of ``protocol`` (see the module docstring).

    ``progress(done, total)``: called after each rendered frame (``psyop audit`` prints a progress line).
    ``mesh_files``: the models validation read (psyop.mesh.MeshFiles); each is loaded once per audit, not per frame."""
    from psyop.rendering import RenderSettings
    from psyop.rendering.renderer import create_headless_context
    from psyop.session.plan import compile_plan
    from psyop.stimulus import build_scene, scene_origin_m
    from psyop.stimulus.build import output_for
    from psyop.stimulus.meshes import SessionMeshes

    plan = compile_plan(protocol, tracker_ipd_m=settings.ipd_m)
    display = dataclasses.replace(plan.display, width_px=max(16, round(plan.display.width_px * settings.scale)),
                                  height_px=max(16, round(plan.display.height_px * settings.scale)))
    px_scale = (display.width_px / plan.display.width_px) ** 2
    item_ids = [str(item.id) for item in protocol.scene]
    fixation_prefix = _fixation_prefix(protocol)
    owns_ctx = ctx is None
    ctx = ctx if ctx is not None else create_headless_context()
    measurer = FrameMeasurer(ctx, RenderSettings(samples_per_axis=settings.samples_per_axis, reuse_tolerance_px=None))
    records: list[FrameRecord] = []
    drawn: list[tuple[Scene, EyeCamera]] = []  # each frame's scene and camera, kept for the sheet's crop
    crop: SheetCrop | None = None
    meshes = SessionMeshes(base_dir, mesh_files)
    try:
        frames = list(iter_frames(plan, settings))
        for done, (frame, phase) in enumerate(frames, 1):
            centre = plan.rig.centre_m(frame.eye)
            scene = build_scene(protocol, frame.row, frame.time_s, centre, interval=frame.interval, base_dir=base_dir,
                                show=phase.primitives, meshes=meshes)
            origin = scene_origin_m(protocol, centre)
            fixation = fixation_point(scene, fixation_prefix, origin, frame.gaze_index, settings.gazes)
            camera = plan.rig.camera(display, frame.eye, fixation, frame.mode, row=frame.row)
            image, areas, mesh_checks = _measure(measurer, scene, camera, px_scale, settings,
                                                 f"{protocol.source_name or protocol.study.name}: cannot render "
                                                 f"{frame.label}")
            transfer = output_for(protocol, base_dir).transfer
            lum = (luminance_checks(ctx, scene, camera, transfer, measurer.settings)
                   if transfer is not None and scene.output is not None else ())
            names = tuple(p.name for p in scene.primitives)
            records.append(FrameRecord(frame, names, tuple(item_of(n, item_ids) for n in names),
                                       tuple(float(a) for a in areas),
                                       hidden_by(scene.primitives, camera.centre_of_projection_m), image,
                                       _point3(camera.centre_of_projection_m),
                                       _px_per_m_shift(scene, camera, display), mesh_checks, lum))
            if settings.sheet_crop:
                drawn.append((scene, camera))
            if progress is not None:
                progress(done, len(frames))
        if drawn:
            crop, records = _in_sheet_crop(measurer, drawn, records, settings.scale, fixation_prefix)
    finally:
        measurer.release()
        if owns_ctx:
            ctx.release()
    min_visible = MIN_VISIBLE_SAMPLES / settings.samples_per_axis**2 / px_scale
    failures, notes = _check(records, item_ids, min_visible, protocol.response.identical_conditions())
    return AuditReport(str(protocol.study.name), settings, tuple(records), tuple(failures), tuple(notes), crop)


def _in_sheet_crop(measurer: FrameMeasurer, drawn: list[tuple[Scene, EyeCamera]], records: list[FrameRecord],
                   scale: float, fixation_prefix: str | None) -> tuple[SheetCrop | None, list[FrameRecord]]:
    """The sheet's crop over every frame (psyop.audit.crops) and the records with their frames rendered in it. The
    window frames the stimulus: a fixation target's primitives (its path may circle far around it) are left out of
    it unless the scene has nothing else."""
    from psyop.audit.masks import screen_boxes_px, zoom_camera

    if any(scene.meshes for scene, _ in drawn):
        return None, records  # a mesh has no screen box here: whole frames
    boxes = []
    for scene, cam in drawn:
        frame_boxes = screen_boxes_px(scene, cam)
        stimulus = np.array([item_of(p.name, [fixation_prefix]) != fixation_prefix if fixation_prefix else True
                             for p in scene.primitives], dtype=bool)
        boxes.append(frame_boxes[stimulus] if stimulus.any() else frame_boxes)
    camera = drawn[0][1]
    crop = sheet_crop(boxes, int(camera.width_px), int(camera.height_px), scale)
    if crop is None:
        return None, records
    images = [measurer.colour(scene, zoom_camera(cam, crop.x0, crop.y0, crop.width_px, crop.height_px,
                                                 crop.magnification)) for scene, cam in drawn]
    return crop, [dataclasses.replace(rec, sheet_image=image) for rec, image in zip(records, images, strict=True)]


def _measure(measurer: FrameMeasurer, scene: Scene, camera: EyeCamera, px_scale: float, settings: AuditSettings,
             where: str) -> tuple[np.ndarray, np.ndarray, tuple[MeshCheck, ...]]:
    """One frame's image, visible areas (display px^2) and mesh checks; a scene the renderer refuses (e.g. more
    primitives than it takes) is a UserError beginning with ``where``."""
    try:
        image = measurer.colour(scene, camera)
        areas = measurer.visible_areas_px(scene, camera) / px_scale
        mesh_checks = (tuple(_in_display_px(c, px_scale) for c in measurer.mesh_checks(scene, camera))
                       if settings.mesh_check else
                       tuple(MeshCheck(m.name, 0.0, 0.0, 0.0, skipped="the audit ran with mesh_check off")
                             for m in scene.meshes))
    except ValueError as error:
        raise UserError(f"{where}: {error}") from None
    return image, areas, mesh_checks


def _in_display_px(check: MeshCheck, px_scale: float) -> MeshCheck:
    """``check``'s areas from audit pixels to display pixels (full resolution)."""
    return dataclasses.replace(check, rendered_px2=check.rendered_px2 / px_scale, exact_px2=check.exact_px2 / px_scale,
                               tolerance_px2=check.tolerance_px2 / px_scale, mismatch_px2=check.mismatch_px2 / px_scale,
                               mismatch_tolerance_px2=check.mismatch_tolerance_px2 / px_scale)


def mesh_findings(records: list[FrameRecord]) -> tuple[list[str], list[str]]:
    """Failures: a mesh whose rendered visible area differs from the exact one by more than its tolerance in a
    frame. Notes: meshes not compared in some frames, and why (the first reason per mesh)."""
    failures: list[str] = []
    skipped: dict[str, tuple[int, str]] = {}
    for rec in records:
        for c in rec.meshes:
            if c.skipped:
                count, why = skipped.get(c.name, (0, c.skipped))
                skipped[c.name] = (count + 1, why)
            elif not c.passed:
                failures.append(f"FAIL mesh {c.name}: rendered silhouette {c.rendered_px2:.4g} px^2, exact ray-triangle "
                                f"{c.exact_px2:.4g} px^2 (off by {c.error_px2:.3g}, allowed {c.tolerance_px2:.3g}; "
                                f"per-pixel mismatch {c.mismatch_px2:.3g}, allowed {c.mismatch_tolerance_px2:.3g}) "
                                f"in {rec.frame.label}")
    notes = [f"note: mesh {name}: silhouette not compared with exact ray-triangle intersection in {count} frame(s): "
             f"{why}" for name, (count, why) in skipped.items()]
    return failures, notes


def _check(records: list[FrameRecord], item_ids: list[str], min_visible: float,
           declared: list[dict[str, str | float]] | None = None) -> tuple[list[str], list[str]]:
    failures: list[str] = []
    notes: list[str] = []
    best: dict[str, float] = {}
    item_of_name: dict[str, str] = {}
    for rec in records:
        for name, item, area in zip(rec.names, rec.items, rec.visible_px2):
            best[name] = max(best.get(name, 0.0), area)
            item_of_name[name] = item
        for ia, ib in rec.hidden_by.items():
            if rec.visible_px2[ia] > min_visible:
                failures.append(f"FAIL {rec.names[ia]} (item {rec.items[ia]}): shows {rec.visible_px2[ia]:.3g} px^2 "
                                f"although {rec.names[ib]} covers it (nearer, or coplanar and listed later) in "
                                f"{rec.frame.label}")
    for name, area in best.items():
        if area <= min_visible:
            hidden = sum(1 for rec in records if name in rec.names and rec.names.index(name) in rec.hidden_by)
            why = f"; geometry hides it in {hidden} of them" if hidden else ""
            frames = sum(1 for rec in records if name in rec.names)
            failures.append(f"FAIL {name} (item {item_of_name[name]}): never visible in {frames} audited frames "
                            f"(largest visible area {area:.3g} px^2){why}")
    shown = set(item_of_name.values()) | {c.name for rec in records for c in rec.meshes}
    for item in item_ids:
        if item not in shown:
            notes.append(f"note: item {item} has no primitive in any audited frame (an aperture, or in no show:)")
    identical, same_centre = _identical_intervals(records, declared or [])
    mesh_failures, mesh_notes = mesh_findings(records)
    return failures + mesh_failures + identical, notes + mesh_notes + same_centre


def _px_per_m_shift(scene: Scene, camera: EyeCamera, display: DisplayProfile) -> float:
    """Image pixels per metre of centre-of-projection shift at the nearest finite primitive
    (its nearest point bounded by its centre distance minus its extent); 0 without finite ones."""
    cop = np.asarray(camera.centre_of_projection_m, dtype=np.float64)
    nearest = math.inf
    for prim in scene.primitives:
        if prim.at_infinity:
            continue
        extent = float(np.linalg.norm(prim.half_u_m) + np.linalg.norm(prim.half_v_m))
        nearest = min(nearest, max(float(np.linalg.norm(np.asarray(prim.centre_m) - cop)) - extent, 1e-3))
    if not math.isfinite(nearest):
        return 0.0
    focal_px = display.width_px / max(float(display.tan_right - display.tan_left), 1e-9)
    return focal_px / nearest


#: a mode-only difference whose largest image shift is below this many audit pixels is a note
UNRESOLVED_SHIFT_PX = 0.5


def _declares(declared: list[dict[str, str | float]], row: TrialRow) -> bool:
    """Whether the protocol declares the trial ``row``'s condition a control whose intervals are meant to render
    identically (``response.identical_intervals``: every factor named has the row's level)."""
    from psyop.protocol.base import format_level

    return any(all(k in row and format_level(row[k]) == format_level(v) for k, v in d.items()) for d in declared)


def _identical_intervals(records: list[FrameRecord], declared: list[dict[str, str | float]]
                         ) -> tuple[list[str], list[str]]:
    """Failures: intervals whose factor values or modes differ but render identically at every
    audited gaze, unless the protocol declares their condition a control (``response: identical_intervals``:
    a note then), and intervals of a declared control that do not render identically. Notes: intervals that
    differ only in mode but whose modes put the centre of projection at the same point at every audited gaze
    (e.g. ocular and reversed at a gaze straight ahead, where N has no x, y part): identical frames are then the
    exact answer, not a bug."""
    from psyop.schedule import interval_values

    by_key: dict[tuple[str, str], dict[int, dict[int, FrameRecord]]] = {}
    for rec in records:
        f = rec.frame
        if not f.is_interval:
            continue
        by_key.setdefault((f.condition, f.eye), {}).setdefault(f.interval, {})[f.gaze_index] = rec
    failures: list[str] = []
    notes: list[str] = []
    for (condition, eye), intervals in by_key.items():
        numbers = sorted(intervals)
        for i, j in zip(numbers, numbers[1:]):
            first, second = intervals[i], intervals[j]
            row = next(iter(first.values())).frame.row
            vi, vj = interval_values(row, i), interval_values(row, j)
            mi, mj = next(iter(first.values())).frame.mode, next(iter(second.values())).frame.mode
            differ = [k for k in vi if k in vj and str(vi[k]) != str(vj[k])] + (["mode"] if mi != mj else [])
            gazes = sorted(set(first) & set(second))
            same = bool(gazes) and all(np.array_equal(first[g].image, second[g].image) for g in gazes)
            if _declares(declared, row):
                if same:
                    notes.append(f"note: condition {condition}, {eye} eye: intervals {i} and {j} render identically, "
                                 "as response.identical_intervals declares (a control)")
                else:
                    failures.append(f"FAIL condition {condition}, {eye} eye: intervals {i} and {j} differ on screen "
                                    "although response.identical_intervals declares them identical (a control); "
                                    "fix the stimulus or the declaration")
                continue
            if not differ:
                continue
            if same:
                what = ", ".join(f"{k} {vi.get(k, mi)} vs {vj.get(k, mj)}" for k in dict.fromkeys(differ))
                shift_px = max(float(np.linalg.norm(np.subtract(first[g].centre_of_projection_m,
                                                                second[g].centre_of_projection_m)))
                               * max(first[g].px_per_m_shift, second[g].px_per_m_shift) for g in gazes)
                if set(differ) == {"mode"} and shift_px < UNRESOLVED_SHIFT_PX:
                    notes.append(f"note: condition {condition}, {eye} eye: intervals {i} and {j} render identically "
                                 f"({what}): the two modes' centres of projection move the nearest surface by at "
                                 f"most {shift_px:.2g} audit pixels at the {len(gazes)} audited gazes, below what "
                                 f"this audit resolves; use a larger --scale or more --gazes to tell them apart")
                    continue
                failures.append(f"FAIL condition {condition}, {eye} eye: intervals {i} and {j} render identically "
                                f"at all {len(gazes)} audited gazes although they differ ({what}); if this "
                                "condition is a control, declare it in response.identical_intervals")
    return failures, notes
