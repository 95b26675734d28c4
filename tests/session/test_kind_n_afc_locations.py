"""``n_afc`` over locations (psyop/protocol/kinds/n_afc.py, protocols/examples/n_afc_locations.yaml): each location
holds the target equally often, the rendered frame shows the target where the schedule put it, a window session
typed under Xvfb, simulated sessions analysed by make figures' script, and bad input at its line."""

from __future__ import annotations

import re
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from kind_helpers import render_frames, run_analysis, variant, window_session
from PIL import Image

from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "protocols" / "examples" / "n_afc_locations.yaml"
LOCATIONS = [(-8.0, 0.0), (0.0, 8.0), (8.0, 0.0), (0.0, -8.0)]


def test_each_location_holds_the_target_equally_often_and_the_schedule_places_it() -> None:
    schedule = compile_schedule(load_protocol(EXAMPLE), 5)
    table = pd.crosstab(schedule["contrast_fraction"], schedule["correct_location"])
    assert list(table.columns) == [1, 2, 3, 4] and (table.to_numpy() == 4).all()
    places = np.array(LOCATIONS)[schedule["correct_location"].to_numpy() - 1]
    assert np.array_equal(schedule[["target_azimuth_deg", "target_elevation_deg"]].to_numpy(), places)
    assert (schedule["mode_interval1"] == "conventional").all() and "correct_interval" not in schedule


def _centroid_px(png: Path) -> tuple[float, float]:
    """The centre of the pixels the noise disc changed (off the grey background), the fixation target's left out."""
    image = np.asarray(Image.open(png).convert("RGB")).astype(int)
    h, w = image.shape[:2]
    yy, xx = np.mgrid[:h, :w]
    changed = np.abs(image - 128).max(axis=-1) > 12
    changed &= (yy - h / 2) ** 2 + (xx - w / 2) ** 2 > 40 ** 2  # the fixation target straight ahead
    assert changed.sum() > 200, changed.sum()
    return float(xx[changed].mean()), float(yy[changed].mean())


def test_the_rendered_frame_shows_the_target_at_the_drawn_location(tmp_path: Path) -> None:
    """At the highest contrast, one trial per location, the eye straight ahead: left and right centroids lie on one
    row at equal distances either side, up and down on one column above and below, each pair about the same
    point (the noise disc is where the schedule put it, and only there)."""
    schedule = compile_schedule(load_protocol(EXAMPLE), 3)
    top = schedule[schedule["contrast_fraction"] == schedule["contrast_fraction"].max()]
    trials = {k: int(top[top["correct_location"] == k].iloc[0]["trial"]) for k in range(1, 5)}
    render_frames(tmp_path, EXAMPLE, 3, [(f"{k}.png", trials[k], 1) for k in trials], gaze_deg="0,0")
    (lx, ly), (ux, uy), (rx, ry), (dx, dy) = (_centroid_px(tmp_path / f"{k}.png") for k in range(1, 5))
    assert lx < ux < rx and uy < ly < dy  # left, up, right, down
    assert abs(ly - ry) < 2 and abs(ux - dx) < 2  # each pair on one row or column
    half_width, half_height = (rx - lx) / 2, (dy - uy) / 2
    assert abs((lx + rx) / 2 - (ux + dx) / 2) < 2 and abs((uy + dy) / 2 - (ly + ry) / 2) < 2
    assert 0.8 < half_width / half_height < 1.25 and half_width > 50  # 8 deg either way, not a speck's offset


def test_a_window_session_typed_under_xvfb(tmp_path: Path) -> None:
    protocol = variant(EXAMPLE, tmp_path, repetitions=1, phase_s=0.03)
    assert window_session(protocol, tmp_path / "data", ["2"]) == "complete"
    trials = pd.read_parquet(tmp_path / "data" / "nafc_locations" / "sub-W1" / "ses-1" / "trials.parquet")
    assert len(trials) == 5 and (trials["response"] == "2").all()
    assert (trials["correct"] == (trials["correct_location"] == 2)).all()


def test_simulated_sessions_are_analysed_with_guess_one_quarter(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                                                 ) -> None:
    from psyop.cli import main as psyop_main

    protocol = variant(EXAMPLE, tmp_path, repetitions=8)
    data, results = tmp_path / "data", tmp_path / "results"
    assert psyop_main(["simulate", "--data", str(data), "--protocols", str(protocol), "--participants", "2"]) == 0
    trials = pd.concat(pd.read_parquet(f) for f in sorted(data.glob("nafc_locations/sub-*/ses-1/trials.parquet")))
    assert (trials["correct"] == (trials["response"].astype(int) == trials["correct_location"])).all()
    by_level = trials.groupby("contrast_fraction")["correct"].mean()
    assert by_level.iloc[0] < 0.6 < 0.85 < by_level.iloc[-1]  # near 1/4 at 0.02, near 1 at 0.32
    assert run_analysis(monkeypatch, "n_afc", ["--study", "nafc_locations", "--data", str(data), "--results",
                                               str(results), "--out", str(tmp_path / "fig.png")]) == 0
    fits = pd.read_csv(results / "nafc_locations_n_afc_fits.csv")
    assert len(fits) == 2 and (fits["guess"] == 0.25).all()
    # levels are contrast fractions: every level-valued column says so, none claims diopters
    assert {"threshold_fraction", "threshold_ci_low_fraction", "width_fraction", "level_max_fraction"} <= set(fits)
    assert not [name for name in fits if name.endswith("_D")], list(fits)
    assert fits["level_max_fraction"].max() == pytest.approx(0.32)
    summary = json.loads((results / "nafc_locations.json").read_text())
    assert summary["level_unit"] == "fraction"
    assert summary["observers"] == ["psychometric_nafc"]  # who answered, from session.json
    assert {r["measure"] for r in summary["thresholds"]} == {"threshold_fraction"}


@pytest.mark.parametrize(("old", "new", "says"), [
    ("locations_deg: [[-8, 0], [0, 8], [8, 0], [0, -8]]", "locations_deg: [[-8, 0], [0, 8], [8, 0]]",
     "needs locations_deg with n = 4 places"),
    ("[0, -8]]", "[0, -80]]", "location 4 at [0, -80] deg is outside the display's field of view"),
    ("[0, -8]]", "[-8, 0]]", "two locations are the same place"),
    ("target: {mode: conventional}          #", "reference: {mode: ocular}\n  target: {mode: conventional}  #",
     "a reference is not shown; remove it"),
    ("centre_deg: [{factor: target_azimuth_deg}, {factor: target_elevation_deg}]", "centre_deg: [8, 0]",
     "nothing in the scene is placed at the drawn location"),
    ("alternatives: locations", "alternatives: intervals", "locations_deg places the target in alternatives"),
])
def test_bad_input_is_one_line_with_its_place(tmp_path: Path, capsys: pytest.CaptureFixture[str], old: str, new: str,
                                              says: str) -> None:
    from psyop.cli import main as psyop_main

    protocol = variant(EXAMPLE, tmp_path, replace=((old, new),))
    assert psyop_main(["validate", str(protocol)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and says in err, err
    assert all(re.search(r"n_afc_locations\.yaml:\d+:\d+: ", line) for line in err.splitlines()), err
