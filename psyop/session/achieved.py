"""session.json's ``display_output``: whether the session's stimuli went through a display calibration (which, and
how), and on a calibrated display the luminance and contrast each calibrated stimulus achieves after quantisation,
per scene item and level (docs/calibration.md).

Each scene item with a surface given in cd/m² is measured alone (:class:`psyop.stimulus.achieved.LuminanceMeter`:
the final pass, the wholly covered pixels, achieved against intended) at every distinct combination of the levels
of the factors its fields read that the schedule holds, in every interval (an interval's ``set:`` included). An
adaptive factor's levels are the ones its procedure can place: the QUEST+ stimulus grid; a staircase's levels are
known only at run time, and such an item is listed under ``not_measured`` (``psyop audit --level`` measures any).
The view: the first rendered eye, straight ahead, conventional mode, the frame cropped to the item's screen box
(the same pixels as the full frame's), without anti-aliasing (each pixel is its centre's ray, so the pixels counted
hold the item alone: ``psyop audit`` counts the wholly covered pixels of its supersampled frames instead); a
solid's one frame, a pattern's pixels averaged over :data:`PATTERN_FRAMES` successive frames (the temporal dither).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from psyop.protocol.factor_fields import factor_fields
from psyop.protocol.luminance import output_record
from psyop.records import JsonObject, TrialRow
from psyop.schedule import interval_values

#: frames a pattern's achieved luminance is averaged over (a solid's dither is spatial only: one frame)
PATTERN_FRAMES = 8

if TYPE_CHECKING:
    import pandas as pd

    from psyop.optics.camera import EyeCamera
    from psyop.optics.transfer import DisplayTransfer
    from psyop.protocol.model import Protocol
    from psyop.rendering.scene import Primitive
    from psyop.session.plan import SessionPlan
    from psyop.stimulus.achieved import LuminanceMeter


def _calibrated_items(protocol: Protocol) -> list[tuple[str, set[str]]]:
    """(item id, the factors its fields read) of every scene item with a surface in cd/m²."""
    out = []
    for item in protocol.scene:
        surfaces = [getattr(item, name, None) for name in ("surface", "left", "right")]
        if any(getattr(s, "luminance", None) is not None for s in surfaces):
            out.append((item.id, {ref.factor for _, ref in factor_fields(item)}))
    return out


def _level_rows(protocol: Protocol, schedule: pd.DataFrame, factors: set[str], intervals: int
                ) -> tuple[list[TrialRow], str | None]:
    """One row of values per distinct level combination of ``factors`` over the schedule's rows and intervals (an
    adaptive factor over its QUEST+ grid), and why some could not be listed (a staircase), or None."""
    from psyop.adaptive.quest_plus import QuestPlusSpec
    from psyop.adaptive.session import adaptive_plan, row_at_level

    plan = adaptive_plan(protocol)
    grid: tuple[float, ...] = ()
    if plan is not None and plan.factor in factors:
        if not isinstance(plan.spec, QuestPlusSpec):
            return [], f"{plan.factor} is placed by a staircase: its levels are known only at run time"
        grid = plan.spec.stimulus
    seen: dict[tuple[tuple[str, float], ...], TrialRow] = {}
    for row in schedule.to_dict("records"):
        expanded = [row_at_level(plan, row, level) for level in grid] if grid and plan is not None else [row]
        for full in expanded:
            for k in range(1, max(1, intervals) + 1):
                values = interval_values(full, k)
                key = tuple((f, float(values[f])) for f in sorted(factors) if f in values)
                if all(math.isfinite(v) for _, v in key):
                    seen.setdefault(key, values)
    return list(seen.values()), None


def _cropped(camera: EyeCamera, prim: Primitive) -> EyeCamera:
    """``camera`` cropped to the primitive's screen box (2 px margin; the whole frame if unbounded)."""
    from psyop.rendering.camera_math import crop_camera
    from psyop.rendering.screen_bounds import screen_bounds_px

    cop = np.asarray(camera.centre_of_projection_m, dtype=np.float64)
    box = screen_bounds_px((np.asarray(prim.centre_m) - cop)[None], np.asarray(prim.half_u_m)[None],
                           np.asarray(prim.half_v_m)[None], np.asarray(camera.pixel_to_ray), camera.width_px,
                           camera.height_px)[0]
    x0, y0 = max(0, int(math.floor(box[0])) - 2), max(0, int(math.floor(box[1])) - 2)
    x1, y1 = min(camera.width_px, int(math.ceil(box[2])) + 2), min(camera.height_px, int(math.ceil(box[3])) + 2)
    if x1 <= x0 or y1 <= y0:
        return camera
    return crop_camera(camera, x0, y0, x1 - x0, y1 - y0)


def _measure_item(meter: LuminanceMeter, transfer: DisplayTransfer, protocol: Protocol, plan: SessionPlan,
                  base_dir: Path | None, item_id: str, rows: list[TrialRow], factors: set[str]) -> list[JsonObject]:
    """The achieved records of one item at each level row."""
    from psyop.rendering import Solid
    from psyop.stimulus import build_scene

    eye = plan.rig.eyes[0]
    centre = plan.rig.centre_m(eye)
    out: list[JsonObject] = []
    for values in rows:
        scene = build_scene(protocol, values, 0.0, centre, interval=1, base_dir=base_dir, show=[item_id])
        camera = plan.rig.camera(plan.display, eye, centre + np.array([0.0, 0.0, -1.0]), "conventional", row=values)
        for prim in scene.primitives:
            frames = 1 if isinstance(prim.material, Solid) else PATTERN_FRAMES
            check = meter.measure_primitive(prim, scene, _cropped(camera, prim), transfer, frames)
            if check is None:
                continue
            out.append({"item": item_id, "primitive": check.name,
                        "levels": {f: float(values[f]) for f in sorted(factors) if f in values},
                        "pixels": check.pixels, "intended_cd_m2": check.intended_cd_m2,
                        "achieved_cd_m2": check.achieved_cd_m2, "intended_contrast": check.intended_contrast,
                        "achieved_contrast": check.achieved_contrast})
    return out


def display_output(protocol: Protocol, schedule: pd.DataFrame, plan: SessionPlan, base_dir: Path | None
                   ) -> JsonObject:
    """session.json's ``display_output`` (:func:`psyop.protocol.luminance.output_record`), with ``achieved`` (a list
    of per item, primitive and level records: pixels, intended and achieved mean cd/m² and contrast) and
    ``not_measured`` (item id -> why) on a calibrated display."""
    from psyop.protocol.luminance import protocol_transfer
    from psyop.rendering import RenderSettings
    from psyop.rendering.renderer import AntiAliasing, create_headless_context
    from psyop.stimulus import interval_phases
    from psyop.stimulus.achieved import LuminanceMeter

    record = output_record(protocol, base_dir)
    transfer = protocol_transfer(protocol, base_dir)
    if transfer is None:
        return record
    items = _calibrated_items(protocol)
    record["achieved_method"] = ("each item alone through the final pass (a solid one frame, a pattern the mean of "
                                 f"{PATTERN_FRAMES} successive frames per pixel), in the first eye's "
                                 "straight-ahead conventional view without anti-aliasing (each pixel its centre's "
                                 "ray: no edge mixing), over the pixels whose centre it covers; achieved = the codes "
                                 "through the calibration's model")
    achieved: list[JsonObject] = []
    not_measured: dict[str, str] = {}
    try:
        ctx = create_headless_context()
    except Exception as exc:  # noqa: BLE001 - no OpenGL here: the session runs, and says what was not measured
        record.update(achieved=[], not_measured={i: f"no OpenGL context ({exc})" for i, _ in items})
        return record
    try:
        with LuminanceMeter(ctx, RenderSettings(antialiasing=AntiAliasing.NONE, reuse_tolerance_px=None)) as meter:
            for item_id, factors in items:
                rows, why = _level_rows(protocol, schedule, factors, len(interval_phases(protocol)))
                if why is not None:
                    not_measured[item_id] = why
                    continue
                achieved += _measure_item(meter, transfer, protocol, plan, base_dir, item_id, rows, factors)
    finally:
        ctx.release()
    record.update(achieved=achieved, not_measured=not_measured)
    return record
