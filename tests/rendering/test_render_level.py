"""`psyop render --level`: an adaptive protocol's trial is rendered at a chosen level (issue 18: it
stopped with 'depth resolves to nan D'); the level changes the rendered frame."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np

from psyop.cli import main

ADAPTIVE = str(Path(__file__).resolve().parents[2] / "protocols" / "examples" / "detection_quest_plus.yaml")


def _render(tmp_path: Path, name: str, *extra: str) -> tuple[np.ndarray, dict]:
    out = tmp_path / f"{name}.png"
    assert main(["render", ADAPTIVE, "--trial", "0", "--mode", "ocular", "--gaze-deg", "8,0",
                 "--antialiasing", "none", "--crop", "560,640,320,320", *extra, "--out", str(out)]) == 0
    return mpimg.imread(out), json.loads(Path(str(out) + ".json").read_text())


def test_render_previews_an_adaptive_trial_at_a_level(tmp_path: Path) -> None:
    start, start_meta = _render(tmp_path, "start")
    assert start_meta["adaptive_level"] == 0.5  # the procedure's start level when none is given
    low, low_meta = _render(tmp_path, "low", "--level", "0.1")
    high, high_meta = _render(tmp_path, "high", "--level", "1.4")
    assert (low_meta["adaptive_level"], high_meta["adaptive_level"]) == (0.1, 1.4)
    assert not np.array_equal(low, high) and not np.array_equal(start, high)
