"""The audit's table and contact sheet.

Table: one line per rendered primitive; per rendering mode the smallest and largest visible
area over the audited frames in that mode, in display pixels (full resolution), and how many of
those frames exact geometry says hide it (``hid``). A primitive's change with mode is read across
a line: e.g. the detection study's red back disc is 0 in conventional frames and a crescent of
a few px^2 in ocular frames at non-zero levels.

Mesh table (:func:`mesh_table`): one line per mesh item; per mode the range of its exact visible
area and the worst disagreement of its rendered silhouette with it (:mod:`psyop.audit.meshes`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from psyop.audit.meshes import (EDGE_PIXEL_TOLERANCE, EXACT_SAMPLES_PER_AXIS, MESH_AREA_FLOOR_WINDOW_PX, MESH_AREA_RELATIVE_TOLERANCE,
                                MSAA_SAMPLES)
from psyop.audit.luminance import luminance_table
from psyop.audit.run import AuditReport, FrameRecord

MODES = ("conventional", "ocular", "reversed")


def format_table(report: AuditReport) -> str:
    names: dict[str, str] = {}
    stats: dict[tuple[str, str], list[float]] = {}
    hidden: dict[tuple[str, str], int] = {}
    for rec in report.records:
        for i, (name, item, area) in enumerate(zip(rec.names, rec.items, rec.visible_px2)):
            names.setdefault(name, item)
            stats.setdefault((name, rec.frame.mode), []).append(area)
            hidden[(name, rec.frame.mode)] = hidden.get((name, rec.frame.mode), 0) + (i in rec.hidden_by)
    modes = [m for m in MODES if any(k[1] == m for k in stats)]
    width = max([9] + [len(n) for n in names])
    item_width = max([4] + [len(i) for i in names.values()])
    head = f"{'primitive':<{width}}  {'item':<{item_width}}" + "".join(
        f"  {m + ' px^2 min..max (hid/frames)':>40}" for m in modes)
    lines = [f"psyop audit: {report.protocol_name}: {len(report.records)} frames at scale {report.settings.scale:g}, "
             f"{report.settings.gazes} gaze(s) per phase and eye; areas in display pixels", head, "-" * len(head)]
    for name, item in names.items():
        cells = []
        for m in modes:
            values = stats.get((name, m))
            if not values:
                cells.append(f"  {'-':>40}")
                continue
            cells.append(f"  {f'{min(values):9.2f} ..{max(values):9.2f} ({hidden[(name, m)]}/{len(values)})':>40}")
        lines.append(f"{name:<{width}}  {item:<{item_width}}" + "".join(cells))
    lines += mesh_table(report, modes)
    lines += luminance_table([(rec.frame.label, check) for rec in report.records for check in rec.luminance])
    lines += list(report.notes)
    lines += list(report.failures) if report.failures else ["PASS: every primitive is seen, none shows where it is "
                                                             "covered, differing intervals render differently"
                                                             + (", every mesh silhouette matches exact ray-triangle "
                                                                "intersection" if _has_meshes(report) else "")]
    return "\n".join(lines)


def _has_meshes(report: AuditReport) -> bool:
    return any(c for rec in report.records for c in rec.meshes if not c.skipped)


def mesh_table(report: AuditReport, modes: list[str]) -> list[str]:
    """Lines per mesh item: per mode the exact visible area's range over the compared frames, the worst
    disagreement of the rendered visible area with it and the worst silhouette mismatch (sum of per-pixel
    coverage differences), both in percent of the exact area, and the frames compared."""
    stats: dict[tuple[str, str], list[tuple[float, float, float]]] = {}
    names: list[str] = []
    for rec in report.records:
        for c in rec.meshes:
            if c.name not in names:
                names.append(c.name)
            if not c.skipped:
                mismatch = c.mismatch_px2 / c.exact_px2 if c.exact_px2 > 0 else (0.0 if c.mismatch_px2 == 0 else float("inf"))
                stats.setdefault((c.name, rec.frame.mode), []).append((c.exact_px2, c.relative_error, mismatch))
    if not names:
        return []
    modes = [m for m in MODES if any(k[1] == m for k in stats)] or modes
    width = max([9] + [len(n) for n in names])
    head = f"{'mesh':<{width}}" + "".join(f"  {m + ' exact px^2 min..max, area/mismatch %':>52}" for m in modes)
    lines = [f"mesh silhouettes: rendered (MSAA {MSAA_SAMPLES} samples) against exact ray-triangle intersection "
             f"({EXACT_SAMPLES_PER_AXIS}x{EXACT_SAMPLES_PER_AXIS} rays per pixel); allowed "
             f"area {100 * MESH_AREA_RELATIVE_TOLERANCE:g} % + {MESH_AREA_FLOOR_WINDOW_PX:g} window px, mismatch "
             f"{EDGE_PIXEL_TOLERANCE:g} px per edge pixel", head, "-" * len(head)]
    for name in names:
        cells = []
        for m in modes:
            values = stats.get((name, m))
            if not values:
                cells.append(f"  {'-':>52}")
                continue
            exact = [v[0] for v in values]
            cell = (f"{min(exact):9.1f} ..{max(exact):9.1f}, {100 * max(v[1] for v in values):6.3f} / "
                    f"{100 * max(v[2] for v in values):6.3f} ({len(values)})")
            cells.append(f"  {cell:>52}")
        lines.append(f"{name:<{width}}" + "".join(cells))
    return lines


def _column_of(rec: FrameRecord) -> tuple[str, int]:
    return (rec.frame.phase, rec.frame.gaze_index)


def column_labels(report: AuditReport) -> list[tuple[str, int]]:
    """The contact sheet's columns in order: (phase name, gaze index), by the phase's place in the trial."""
    order = sorted({(rec.frame.phase_index, rec.frame.phase, rec.frame.gaze_index) for rec in report.records})
    return [(phase, gaze) for _, phase, gaze in order]


def _cell(rec: FrameRecord) -> np.ndarray:
    """What a sheet cell shows: the frame in the sheet's crop when the audit made one, else the whole frame."""
    return rec.image if rec.sheet_image is None else rec.sheet_image


def write_contact_sheet(report: AuditReport, path: Path, gap_px: int = 2) -> None:
    """A PNG of every audited frame: one row per (condition, eye), one column per (phase, gaze),
    with the row's condition and eye written at its left and each column's phase and gaze above it
    (:func:`column_labels`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows: dict[tuple[str, str], list] = {}
    for rec in report.records:
        rows.setdefault((rec.frame.condition, rec.frame.eye), []).append(rec)
    if not rows:
        raise ValueError("no frames to put on a contact sheet")
    cropped = report.sheet_crop is not None
    h, w = _cell(report.records[0]).shape[:2]
    columns = column_labels(report)
    n_cols = max(len(columns), max(len(r) for r in rows.values()))
    label_px, header_px = 260, 52 if cropped else 36
    sheet = np.ones((header_px + len(rows) * (h + gap_px) + gap_px, label_px + n_cols * (w + gap_px) + gap_px, 3),
                    np.float32)
    for r, recs in enumerate(rows.values()):
        for rec in recs:
            c = columns.index(_column_of(rec))
            y, x = header_px + gap_px + r * (h + gap_px), label_px + gap_px + c * (w + gap_px)
            sheet[y:y + h, x:x + w] = np.clip(_cell(rec), 0.0, 1.0)
    dpi = 100
    fig = plt.figure(figsize=(sheet.shape[1] / dpi, sheet.shape[0] / dpi), dpi=dpi)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.imshow(sheet, interpolation="nearest")
    ax.set_axis_off()
    for r, (condition, eye) in enumerate(rows):
        ax.text(4, header_px + gap_px + r * (h + gap_px) + h / 2, f"{condition}\n{eye} eye", fontsize=7, va="center")
    for c, (phase, gaze) in enumerate(columns):
        ax.text(label_px + gap_px + c * (w + gap_px) + w / 2, header_px - 18, f"{phase}\ngaze {gaze}", fontsize=7,
                ha="center", va="center")
    if report.sheet_crop is not None:
        ax.text(4, 8, report.sheet_crop.describe(report.settings.scale), fontsize=7, va="center")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    from psyop.atomic import write_atomic

    try:
        write_atomic(path, lambda handle: fig.savefig(handle, format=path.suffix.lstrip(".") or "png", dpi=dpi))
    finally:
        plt.close(fig)
