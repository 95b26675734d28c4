"""Sizes and contrasts as factor levels (issue 18: only depth could vary; a contrast factor was
validated and then used by nothing, so its conditions looked the same). Checked in rendered frames
against the geometry of the protocol's angles, not against the schedule."""

from __future__ import annotations

import json
import math
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest

from psyop.cli import main
from psyop.errors import UserError
from psyop.protocol import parse_protocol
from psyop.schedule import compile_schedule

PROTOCOL = """psyop_protocol: 1
study: {name: contrast_size, title: contrast detection at two sizes}
display: {profile: vive_pro, eye_model: gullstrand_emsley_relaxed, ipd: {mm: 64}}
eyes: right
scene:
  - id: patch
    kind: disc
    size_deg: {factor: size_deg}
    depth: {D: 1}
    surface: {kind: white_noise, grain_deg: 0.2, mean: 0.7, contrast: {factor: contrast_fraction}}
trial:
  phases:
    - {kind: interval, duration_s: 1}
    - {kind: interval, duration_s: 1}
    - {kind: response, expected_s: 1}
design:
  factors:
    size_deg: {levels: [2, 6]}
    contrast_fraction: {levels: [0.1, 0.3]}
  repetitions: 2
  randomisation: {kind: sequential}
response:
  kind: two_interval
  test: {mode: conventional}
  reference: {mode: conventional, set: {contrast_fraction: 0}}
  level_factor: contrast_fraction
  order: balanced
"""


def _render(tmp_path: Path, trial: int, interval: int) -> tuple[np.ndarray, dict]:
    path = tmp_path / "p.yaml"
    path.write_text(PROTOCOL)
    out = tmp_path / f"t{trial}_{interval}.png"
    assert main(["render", str(path), "--trial", str(trial), "--interval", str(interval), "--antialiasing", "none",
                 "--out", str(out)]) == 0
    return (mpimg.imread(out)[..., :3] * 255).round(), json.loads(Path(str(out) + ".json").read_text())


def _expected_area_px(size_deg: float, meta: dict) -> float:
    """A disc of size_deg seen straight ahead from the centre of projection (conventional, gaze 0,0):
    radius tan(size/2) in image-plane tangents, times pixels per tangent on each axis."""
    t = meta["frustum_tangents"]
    width, height = meta["resolution_px"]
    r = math.tan(math.radians(size_deg / 2))
    return math.pi * (r * width / (t["right"] - t["left"])) * (r * height / (t["top"] - t["bottom"]))


def test_size_and_contrast_levels_change_the_rendered_frame_as_documented(tmp_path: Path) -> None:
    protocol = parse_protocol(PROTOCOL, "p.yaml")
    schedule = compile_schedule(protocol, 0)
    background = 0.5 * 255
    spreads = {}
    for size in (2.0, 6.0):
        for contrast in (0.1, 0.3):
            row = schedule[(schedule["size_deg"] == size) & (schedule["contrast_fraction"] == contrast)].iloc[0]
            test = int(row["correct_interval"])
            for interval in (1, 2):
                image, meta = _render(tmp_path, int(row["trial"]), interval)
                inside = np.any(np.abs(image - background) > 1, axis=-1)
                area = float(inside.sum())
                assert area == pytest.approx(_expected_area_px(size, meta), rel=0.02), (size, interval)
                spread = float(image[inside].std())
                if interval == test:
                    spreads[(size, contrast)] = spread
                else:  # the reference's contrast is set to 0: a uniform disc
                    assert spread < 1.0
    for size in (2.0, 6.0):  # three times the contrast: three times the grey-level spread (peak contrast around the mean)
        assert spreads[(size, 0.3)] / spreads[(size, 0.1)] == pytest.approx(3.0, rel=0.1)


def test_a_level_outside_a_fields_range_is_refused_at_its_line() -> None:
    text = PROTOCOL.replace("contrast_fraction: {levels: [0.1, 0.3]}", "contrast_fraction: {levels: [0.1, 1.4]}")
    with pytest.raises(UserError) as info:
        parse_protocol(text, "p.yaml")
    message = str(info.value)
    assert "contrast_fraction = 1.4 does not fit this field" in message and "less than or equal to 1" in message
    line = int(info.value.location.split(":")[1])
    assert "contrast: {factor: contrast_fraction}" in text.splitlines()[line - 1]
    with pytest.raises(UserError, match="'sise_deg' is not a factor"):
        parse_protocol(PROTOCOL.replace("{factor: size_deg}", "{factor: sise_deg}"), "p.yaml")


PLACED = PROTOCOL.replace("    size_deg: {factor: size_deg}\n", "    size_deg: 2\n    centre_deg: [{factor: azimuth_deg}, {factor: elevation_deg}]\n") \
    .replace("    size_deg: {levels: [2, 6]}\n", "    azimuth_deg: {levels: [-12, 20]}\n    elevation_deg: {levels: [0, 8]}\n")


def test_a_disc_centre_as_factor_levels_lands_where_its_angles_say(tmp_path: Path) -> None:
    """The disc's centre from azimuth/elevation factors: the rendered disc's centroid is where the
    direction (az, el) from the eye's centre projects (conventional, gaze ahead), within 0.5 px."""
    from psyop.optics.camera import make_eye_camera
    from psyop.protocol.display import resolve_display_profile
    from psyop.rendering.builders import direction_from_angles
    from psyop.rendering.camera_math import project_points_px

    path = tmp_path / "placed.yaml"
    path.write_text(PLACED)
    protocol = parse_protocol(PLACED, str(path))
    schedule = compile_schedule(protocol, 0)
    display = resolve_display_profile(protocol.display)
    centre = np.array([0.032, 0.0, 0.0])
    camera = make_eye_camera(display, "right", centre + np.array([0.0, 0.0, -1.0]), 0.064, 0.0076916, "conventional")
    seen = set()
    for _, row in schedule.iterrows():
        key = (row["azimuth_deg"], row["elevation_deg"])
        if key in seen:
            continue
        seen.add(key)
        out = tmp_path / f"p{len(seen)}.png"
        assert main(["render", str(path), "--trial", str(int(row["trial"])), "--interval", str(int(row["correct_interval"])),
                     "--antialiasing", "none", "--out", str(out)]) == 0
        image = (mpimg.imread(out)[..., :3] * 255).round()
        ys, xs = np.nonzero(np.any(np.abs(image - 127.5) > 1, axis=-1))
        expected = project_points_px(camera, [centre + direction_from_angles(*key) * 1.0])[0]
        # a frontoparallel disc projects onto the (parallel) image plane as a circle about its centre's image
        assert abs(xs.mean() + 0.5 - expected[0]) < 0.5 and abs(ys.mean() + 0.5 - expected[1]) < 0.5, key
    assert len(seen) == 4
