"""Figures and summaries of threshold studies whose conditions are not numbers (issue 41, item 5).

Protocols psyop does not ship (tests/unshipped_protocols.py): a condition factor of words, numbers and
words crossed, and gaze validation with quality: rules. Each is simulated (two participants, a few
trials), then analysed by the scripts `make figures` runs, in the order it runs them: the fits, the
thresholds figure, the psychometric supplement, the gaze-quality figure and the summary. None may crash
(`make figures` ended in "can only concatenate str (not numpy.float64) to str" on a factor of words).
"""

from __future__ import annotations

import importlib
import json
import sys
from pathlib import Path

import pandas as pd
import pytest

from psyop.cli import main as cli_main
from psyop.statistics.conditions import CELL_COLUMN
from tests import unshipped_protocols

ANALYSIS = Path(__file__).resolve().parents[2] / "analysis"


def _script(name: str):
    if str(ANALYSIS) not in sys.path:
        sys.path.insert(0, str(ANALYSIS))
    return importlib.import_module(name)


def _analyse(tmp: Path, shape: str) -> tuple[str, Path, Path, Path]:
    """Simulate the shape's study (2 participants) and run its analysis scripts; (study, data, results, figures)."""
    protocol = unshipped_protocols.write(tmp, shape)
    study = protocol.stem
    data, res, fig = tmp / "data", tmp / "results", tmp / "figures"
    assert cli_main(["simulate", "--data", str(data), "--protocols", str(protocol), "--participants", "2",
                     "--jobs", "1"]) == 0
    common = ["--study", study, "--data", str(data), "--results", str(res)]
    fits = str(res / f"{study}_fits.csv")
    assert _script("fit_psychometric").main([*common, "--out", fits, "--n-jobs", "1", "--n-bootstrap", "50",
                                             "--grid-scale", "0.5"]) == 0
    assert _script("fig_detection_thresholds").main([*common, "--fits", fits, "--out",
                                                     str(fig / f"{study}_thresholds.png")]) == 0
    assert _script("supp_psychometric_functions").main([*common, "--fits", fits, "--out",
                                                        str(fig / f"supp_psychometric_{study}.png")]) == 0
    assert _script("gaze_quality").main([*common, "--out", str(fig / f"{study}_gaze_quality.png")]) == 0
    assert _script("results_table").main(["--data", str(data), "--results", str(res), "--out",
                                          str(res / "summary.md")]) == 0
    return study, data, res, fig


@pytest.mark.parametrize("shape, condition", [("words", "mode"), ("mixed", CELL_COLUMN), ("validated", "mode")])
def test_figures_and_summaries_of_any_factor_type(tmp_path: Path, shape: str, condition: str) -> None:
    study, _, res, fig = _analyse(tmp_path, shape)
    for name in (f"{study}_thresholds", f"supp_psychometric_{study}", f"{study}_gaze_quality"):
        assert (fig / f"{name}.png").stat().st_size > 0 and (fig / f"{name}.pdf").is_file(), name
    fits = pd.read_csv(res / f"{study}_fits.csv")
    assert set(fits["condition_column"]) == {condition}
    thresholds = json.loads((res / f"{study}_thresholds.json").read_text())
    assert thresholds["condition_column"] == condition
    summary = (res / f"{study}_summary.md").read_text()
    if shape == "mixed":  # every cell its own condition, named by both factors' levels
        assert set(fits[CELL_COLUMN]) == {f"back_D={b}, mode={m}" for b in (1, 2) for m in ("ocular", "reversed")}
        assert "the crossed cells of back_D x mode" in summary
    else:
        assert set(fits["mode"]) == {"ocular", "reversed"}
        assert "effect of mode on threshold (rm-ANOVA)" in summary
    if shape == "validated":  # the validation rule was measured, and the summary says what it excluded
        measures = pd.read_csv(res / f"{study}_gaze_quality.csv")
        assert measures["validation_mean_error_deg"].notna().all()
        assert "Gaze-based exclusions" in summary


def test_condition_positions_place_numbers_at_their_value_and_words_in_order() -> None:
    from psyop.figures.study_figures import condition_positions

    assert condition_positions(pd.Series([3.0, 1.0, 1.0])) == ([1.0, 3.0], {1.0: 1.0, 3.0: 3.0}, ["1", "3"])
    cells = pd.Series(["back_D=2, mode=ocular", "back_D=1, mode=reversed"])
    assert condition_positions(cells)[1] == {"back_D=1, mode=reversed": 0, "back_D=2, mode=ocular": 1}


def test_the_summary_leaves_out_a_study_that_failed_in_this_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """analysis/batch.py names the studies that failed (PSYOP_FAILED_STUDIES): their results from an earlier
    run are not summarised as if current, and the summary says they were not analysed."""
    study, data, res, _ = _analyse(tmp_path, "words")
    monkeypatch.setenv("PSYOP_FAILED_STUDIES", study)
    table = _script("results_table")
    code = table.run(lambda: table.main(["--data", str(data), "--results", str(res), "--out", str(res / "summary.md")]))
    assert code == 2  # no other study's results here: nothing to summarise (one line, no traceback)
    assert "Not analysed" in (res / f"{study}_summary.md").read_text()
