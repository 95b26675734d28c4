"""Issue 29, "Done when": a held-out 3-participant reach study through the figure script: every
participant in the analysis, the test's df stated and flagged, and the model actually fitted (mixed
model, or its CR2 fallback) named in the results and the figure's caption."""

from __future__ import annotations

import importlib
import json
import sys
from pathlib import Path

import numpy as np

from psyop.statistics import simulate as sim
from psyop.statistics.dataset import write_dataset

ANALYSIS = Path(__file__).resolve().parents[2] / "analysis"


def test_three_participant_reach_keeps_everyone_flags_few_participants_and_names_its_model(tmp_path, monkeypatch):
    data, results = tmp_path / "data", tmp_path / "results"
    table = sim.simulate_reach(np.random.default_rng(29), n_subjects=3, slope_sd=0.1)
    write_dataset(data, {"reach3": table}, simulated=True, protocol_sha256={"reach3": "c" * 64})
    captions: list[str] = []
    monkeypatch.syspath_prepend(str(ANALYSIS))
    script = importlib.import_module("fig_egocentric_reach")
    real_plot = script.plot_reach

    def spy(*args, **kwargs):
        captions.append(kwargs["test_model"])
        return real_plot(*args, **kwargs)

    monkeypatch.setattr(script, "plot_reach", spy)
    assert script.main(["--data", str(data), "--study", "reach3", "--results", str(results),
                        "--out", str(tmp_path / "reach.png")]) == 0
    payload = json.loads((results / "reach3.json").read_text())
    assert payload["n_subjects"] == 3, "no participant dropped"
    mixed = payload["mixed"]
    assert "few_participants" in mixed["flags"], mixed
    text = payload["summary"]["reach: condition difference, primary (subject-aware)"]
    assert ("chi2(" in text or "F(" in text) and "FEW PARTICIPANTS" in text, text  # its df, and the flag
    (caption,) = captions
    assert caption.startswith(mixed["method"].split(" (")[0]) and "FLAGGED" in caption
    if mixed["method"].startswith("OLS"):
        assert "CR2" in caption and "low_df" in mixed["flags"]
    sys.modules.pop("fig_egocentric_reach", None)
