"""The rendered NC as a factor (display.rendering_nc; the paper's future work needs NC to vary):
each trial is rendered with its level's NC, checked in rendered frames against the exact visible
area of the back disc for a camera with that NC."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest

from psyop.cli import main
from psyop.errors import UserError
from psyop.optics.camera import make_eye_camera
from psyop.protocol import parse_protocol
from psyop.protocol.display import resolve_display_profile
from psyop.rendering.builders import direction_from_angles
from psyop.rendering.camera_math import crop_camera, project_points_px
from psyop.rendering.exact import visible_back_area_px
from psyop.schedule import compile_schedule
from psyop.stimulus import build_scene

REPO = Path(__file__).resolve().parents[2]
DETECTION = (REPO / "protocols" / "detection.yaml").read_text()
TEXT = (DETECTION
        .replace("  ipd: tracker   ", "  ipd: {mm: 64}\n  rendering_nc: {mm: {factor: nc_mm}}   ")
        .replace("    level_D:\n", "    nc_mm: {levels: [4, 12]}\n    level_D:\n")
        .replace("levels: [0, 0.25, 0.5, 0.75, 1]", "levels: [0, 1]")
        .replace("repetitions: 15 ", "repetitions: 2 "))


def test_each_trial_is_rendered_with_its_levels_nc(tmp_path: Path) -> None:
    path = tmp_path / "nc.yaml"
    path.write_text(TEXT)
    protocol = parse_protocol(TEXT, str(path))
    schedule = compile_schedule(protocol, 0)
    display = resolve_display_profile(protocol.display)
    centre = np.array([0.032, 0.0, 0.0])
    gaze = (16.0, 0.0)
    fixation = centre + direction_from_angles(*gaze) * 0.5
    areas = {}
    for nc_mm in (4.0, 12.0):
        row = schedule[(schedule["nc_mm"] == nc_mm) & (schedule["back_D"] == 1.0) & (schedule["level_D"] == 1.0)].iloc[0]
        interval = 1 if row["mode_interval1"] == "ocular" else 2
        exact_camera = make_eye_camera(display, "right", fixation, 0.064, nc_mm / 1000.0, "ocular")
        scene = build_scene(protocol, row.to_dict(), 0.0, centre, interval=interval)
        back, front = (next(p for p in scene.primitives if p.name == n) for n in ("back", "front"))
        c = project_points_px(exact_camera, [back.centre_m])[0]
        x0, y0 = int(c[0]) - 40, int(c[1]) - 40
        out = tmp_path / f"nc{nc_mm:g}.png"
        assert main(["render", str(path), "--trial", str(int(row["trial"])), "--interval", str(interval),
                     "--gaze-deg", "16,0", "--fixation-m", "0.5", "--crop", f"{x0},{y0},80,80", "--out", str(out)]) == 0
        meta = json.loads(Path(str(out) + ".json").read_text())
        assert meta["rendered_nc_m"] == pytest.approx(nc_mm / 1000.0) and meta["mode"] == "ocular"
        image = mpimg.imread(out)[..., :3].astype(np.float64)
        measured = float(np.sum(image[..., 0] - image[..., 1]))  # red minus green: the back disc's visible sliver
        exact = visible_back_area_px(crop_camera(exact_camera, x0, y0, 80, 80), back, front)
        assert measured == pytest.approx(exact, rel=0.05), nc_mm
        # the session's cameras (the plan's rig, given the trial row) use the same NC
        from psyop.session.plan import compile_plan

        session_camera = compile_plan(protocol).rig.camera(display, "right", fixation, "ocular", row=row.to_dict())
        np.testing.assert_allclose(session_camera.centre_of_projection_m, exact_camera.centre_of_projection_m, atol=1e-15)
        areas[nc_mm] = measured
    assert areas[12.0] > 2.5 * areas[4.0]  # the sliver grows with the rendered NC


def test_rendering_nc_levels_are_checked_at_their_line() -> None:
    bad = TEXT.replace("nc_mm: {levels: [4, 12]}", "nc_mm: {levels: [4, 40]}")
    with pytest.raises(UserError) as info:
        parse_protocol(bad, "nc.yaml")
    assert "gives a rendered NC of 40 mm" in str(info.value) and "rendering_nc" in str(info.value)
    unused = TEXT.replace("  rendering_nc: {mm: {factor: nc_mm}}", "")
    with pytest.raises(UserError, match="factor 'nc_mm' is used by nothing"):
        parse_protocol(unused, "nc.yaml")
    metres = TEXT.replace("{factor: nc_mm}}", "{factor: nc_scale_fraction}}").replace("nc_mm: {levels", "nc_scale_fraction: {levels")
    with pytest.raises(UserError, match="name the factor 'nc_scale_fraction' with _mm"):
        parse_protocol(metres, "nc.yaml")
