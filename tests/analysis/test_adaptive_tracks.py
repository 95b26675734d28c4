"""Adaptive runs: reversals found from the logged counts, estimates side by side, a track plot drawn
for every participant x condition (held-out style: a staircase whose floor censors some fits)."""

from __future__ import annotations

import importlib
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from psyop.statistics.adaptive_estimates import estimates_table, mark_reversals

REPO = Path(__file__).resolve().parents[2]


def _track():
    levels = [0.9, 0.7, 0.5, 0.7, 0.6, 0.5, 0.6]
    reversals = [0, 0, 0, 1, 2, 2, 3]
    return pd.DataFrame({"participant": "S01", "back_D": 1.0, "trial_index": range(7), "level_D": levels,
                         "correct": [True] * 7, "adaptive_procedure": "staircase_1u3d",
                         "adaptive_reversals": reversals, "adaptive_estimate_D": np.linspace(0.9, 0.58, 7),
                         "adaptive_estimate_sd_D": 0.05})


def test_reversals_are_the_trials_after_which_the_count_rises_and_estimates_sit_side_by_side():
    t = _track()
    marked = mark_reversals(t.sample(frac=1.0, random_state=1), ["participant", "back_D"])
    assert marked.loc[marked["is_reversal"], "trial_index"].tolist() == [3, 4, 6]
    fits = pd.DataFrame({"participant": ["S01"], "back_D": [1.0], "threshold_D": [0.61], "status": ["ok"]})
    (row,) = estimates_table(t, "level_D", "D", ["participant", "back_D"], fits).to_dict("records")
    assert row["n_reversals"] == 3 and row["reversal_mean"] == pytest.approx((0.7 + 0.6 + 0.6) / 3)
    assert row["procedure_estimate"] == pytest.approx(0.58) and row["fit_threshold_D"] == 0.61
    assert row["fit_status"] == "ok" and row["n_trials"] == 7


def test_held_out_staircase_with_censored_fits_gets_tracks_and_keeps_every_participant(tmp_path):
    """A 2-participant staircase whose floor (0.35 D) lies above good observers' thresholds."""
    src = (REPO / "protocols/examples/detection_quest_plus.yaml").read_text()
    start = src.index("        procedure: quest_plus")
    src = src[:start] + ("        procedure: staircase\n        rule: 1u3d\n        start: 0.9\n        min: 0.35\n"
                         "        max: 1.5\n        step_sizes: [0.2, 0.1, 0.05]\n") + src[src.index("  repetitions: 40"):]
    src = src.replace("name: detection_quest_plus", "name: stair_test", 1).replace("repetitions: 40", "repetitions: 20")
    proto = tmp_path / "stair_test.yaml"
    proto.write_text(src)
    data, res = tmp_path / "data", tmp_path / "results"
    subprocess.run([sys.executable, "-m", "psyop", "simulate", "--data", str(data), "--protocols", str(proto),
                    "--participants", "2", "--jobs", "1"], check=True, capture_output=True)
    sys.path.insert(0, str(REPO / "analysis"))
    try:
        common = ["--data", str(data), "--results", str(res), "--study", "stair_test"]
        assert importlib.import_module("fit_psychometric").main(
            ["--study", "stair_test", "--data", str(data), "--out", str(res / "stair_test_fits.csv"),
             "--n-jobs", "1", "--n-bootstrap", "50"]) == 0
        assert importlib.import_module("adaptive_tracks").main(common + ["--out", str(tmp_path / "tracks.png")]) == 0
        assert importlib.import_module("fig_detection_thresholds").main(common + ["--out", str(tmp_path / "t.png")]) == 0
    finally:
        sys.path.remove(str(REPO / "analysis"))
    assert (tmp_path / "tracks.png").stat().st_size > 10_000
    from psyop.cli.studies import make_rules

    rules, said = make_rules(data, REPO / "protocols")  # `make figures` draws the tracks of an adaptive study
    assert "$(FIGDIR)/stair_test_tracks.png: analysis/adaptive_tracks.py" in rules
    assert "stair_test_tracks.png" in said[0]
    tracks = json.loads((res / "stair_test_adaptive.json").read_text())["tracks"]
    assert len(tracks) == 2 * 3 and all(t["n_trials"] == 20 for t in tracks)
    thresholds = json.loads((res / "stair_test_thresholds.json").read_text())
    c = thresholds["censored"]
    assert c["n_censored_below"] + c["n_censored_above"] == thresholds["n_left_out"], "every censored fit is in the model"
    assert "censored thresholds" in thresholds["summary"]
    anova = {k: v for k, v in thresholds["summary"].items() if "rm-ANOVA" in k}
    assert anova and all("LOW DF" in v or v.startswith(("not computed", "same as above")) for v in anova.values()), \
        anova  # 2 participants: an F with 2 error df or fewer is flagged, never reported bare
