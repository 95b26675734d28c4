"""A two-interval study whose only factor is the level (one threshold per participant) is analysed, not refused
(issue 40): its fits, thresholds figure and psychometric panels are built with the one condition 'all', and the
rm-ANOVA says it has no effect to test instead of a number."""

from __future__ import annotations

import importlib
import json
import sys
from pathlib import Path

import pandas as pd

REPO = Path(__file__).resolve().parents[2]


def _level_only(tmp_path: Path) -> Path:
    text = (REPO / "protocols" / "detection.yaml").read_text()
    for old, new in (("name: detection", "name: level_only"),
                     ("    back_D:\n      levels: [1, 2, 3]                 # Sec. 5.1 Conditions: 1, 2 or 3 D\n", ""),
                     ("depth: {factor: [back_D, level_D]}", "depth: {D: 1, factor: level_D}"),
                     ("{factor: back_D}", "{D: 1}"), ("repetitions: 15", "repetitions: 8")):
        assert old in text, old
        text = text.replace(old, new)
    path = tmp_path / "level_only.yaml"
    path.write_text(text)
    return path


def test_a_study_with_only_the_level_factor_gets_its_thresholds(tmp_path: Path, monkeypatch) -> None:
    from psyop.cli import main

    data, results = tmp_path / "data", tmp_path / "results"
    assert main(["simulate", "--data", str(data), "--protocols", str(_level_only(tmp_path)), "--participants", "3"]) == 0
    common = ["--study", "level_only", "--data", str(data), "--results", str(results)]
    fits = results / "level_only_fits.csv"
    monkeypatch.syspath_prepend(str(REPO / "analysis"))  # the scripts' own imports, as make runs them
    for script, extra in (("fit_psychometric", ["--out", str(fits)]),
                          ("fig_detection_thresholds", ["--fits", str(fits), "--out", str(tmp_path / "t.png")]),
                          ("supp_psychometric_functions", ["--fits", str(fits), "--out", str(tmp_path / "s.png")])):
        try:
            assert importlib.import_module(script).main([*common, *extra]) == 0, script
        finally:
            sys.modules.pop(script, None)
    table = pd.read_csv(fits)
    assert len(table) == 3 and set(table["condition_cell"]) == {"all"}
    summary = json.loads((results / "level_only_thresholds.json").read_text())["summary"]
    effect = next(v for k, v in summary.items() if k.startswith("effect of") and "sensitivity" not in k)
    assert effect.startswith("not applicable: one condition")
    assert (tmp_path / "t.png").stat().st_size > 0 and (tmp_path / "s.png").stat().st_size > 0
