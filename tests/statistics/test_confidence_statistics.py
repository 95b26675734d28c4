"""Confidence after a choice (psyop/statistics/confidence.py, analysis/_confidence.py): the type-2 ROC area against
scipy's Mann-Whitney U, its flags, and recovery from simulated observers with a stated confidence model: confidence
that follows the evidence gives areas above 0.5 and a confidence rising with the level on correct answers; a
confidence independent of correctness gives areas at 0.5 within their intervals."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.session.plan import compile_plan
from psyop.session.responses.simulated import make_observer
from psyop.statistics.confidence import auroc_by_participant, auroc_summary, confidence_means, type2_auroc

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "protocols" / "examples" / "two_interval_confidence.yaml"


def test_the_area_is_the_mann_whitney_u_over_the_pairs_and_its_interval_covers_it() -> None:
    rng = np.random.default_rng(5)
    correct = rng.uniform(size=300) < 0.7
    confidence = np.clip(np.round(1.5 + correct + rng.normal(0, 1, 300)), 1, 4)
    result = type2_auroc(confidence, correct)
    u = stats.mannwhitneyu(confidence[correct], confidence[~correct]).statistic
    assert math.isclose(result.auroc, u / (correct.sum() * (~correct).sum()), rel_tol=1e-12)
    assert result.ci_low < result.auroc < result.ci_high and result.flags == ""
    assert (result.n_correct, result.n_wrong) == (int(correct.sum()), int((~correct).sum()))


def test_no_wrong_answer_or_ordered_pairs_are_flagged_not_silent() -> None:
    none_wrong = type2_auroc(np.array([1, 2, 3]), np.array([True, True, True]))
    assert math.isnan(none_wrong.auroc) and none_wrong.flags == "no_wrong"
    none_right = type2_auroc(np.array([1, 2]), np.array([False, False]))
    assert math.isnan(none_right.auroc) and none_right.flags == "no_correct"
    ordered = type2_auroc(np.array([4, 4, 1, 1]), np.array([True, True, False, False]))
    assert ordered.auroc == 1.0 and "zero_se" in ordered.flags
    spread = auroc_summary(pd.DataFrame({"auroc": [0.55, 0.99]}))  # a t interval past 1, clipped and flagged
    assert spread["ci_high"].iloc[0] == 1.0 and "ci_clipped" in spread["flags"].iloc[0]


def _simulated(protocol_text: str, tmp_path: Path, participants: int, seed: int) -> pd.DataFrame:
    """Trials answered by the protocol's simulated observer (its choice and its confidence), ``participants`` of
    them, each from its own seed, without running sessions."""
    path = tmp_path / "protocol.yaml"
    path.write_text(protocol_text)
    protocol = load_protocol(path)
    params = compile_plan(protocol).observer_params()
    frames = []
    for j in range(participants):
        participant = f"S{j:02d}"
        schedule = compile_schedule(protocol, seed + j)
        observer = make_observer(params, seed=seed + j, participant=participant)
        rows = schedule.to_dict("records")
        answers = [observer.collect(row, 0.0) for row in rows]
        frames.append(schedule.assign(participant=participant, correct=[a.correct for a in answers],
                                      confidence=[observer.confidence(row, 4) for row in rows]))
    return pd.concat(frames, ignore_index=True)


def test_confidence_that_follows_the_evidence_is_recovered_above_chance_and_rises_with_the_level(tmp_path) -> None:
    trials = _simulated(EXAMPLE.read_text(), tmp_path, participants=8, seed=40)
    per = auroc_by_participant(trials)
    summary = auroc_summary(per).iloc[0]
    print(per.to_string(index=False))
    assert summary["ci_low"] > 0.5 and (per["ci_low"] > 0.5).all()
    means = confidence_means(trials, ["level_D"])
    on_correct = means[means["correct"]].set_index("level_D")["mean"]
    assert on_correct.is_monotonic_increasing and on_correct.iloc[-1] - on_correct.iloc[0] > 1.0
    assert trials.groupby("participant")["confidence"].nunique().min() >= 3  # varies between trials


def test_confidence_independent_of_correctness_gives_areas_at_one_half(tmp_path) -> None:
    """evidence_weight 0: the rating is the meta noise alone. Each participant's DeLong interval covers 0.5 at a
    rate a binomial test against 95 % accepts (p > 0.001), and the participants' mean interval covers 0.5."""
    text = EXAMPLE.read_text().replace("    meta_noise_sd: 0.5", "    meta_noise_sd: 1.0\n    evidence_weight: 0")
    text = text.replace("criteria: [0.3, 0.9, 1.5]", "criteria: [-0.7, 0.0, 0.7]")
    trials = _simulated(text, tmp_path, participants=40, seed=400)
    per = auroc_by_participant(trials)
    covered = int(((per["ci_low"] <= 0.5) & (0.5 <= per["ci_high"])).sum())
    print(f"independent confidence: {covered}/{len(per)} intervals cover 0.5")
    assert stats.binom.cdf(covered, len(per), 0.95) > 1e-3, covered
    summary = auroc_summary(per).iloc[0]
    assert summary["ci_low"] <= 0.5 <= summary["ci_high"], summary.to_dict()


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_the_kinds_analysis_writes_the_confidence_tables_and_figure(tmp_path, monkeypatch) -> None:
    """analysis/_confidence.py from a kind's script (analysis/n_afc.py's call, here on the example's trials): its
    tables, its summary and its figure; nothing for trials without the column."""
    import importlib
    import sys

    monkeypatch.syspath_prepend(str(REPO / "analysis"))
    module = importlib.import_module("_confidence")
    try:
        trials = _simulated(EXAMPLE.read_text(), tmp_path, participants=3, seed=7)
        figure = tmp_path / "figures" / "demo_thresholds.png"
        payload = module.confidence_analysis(trials, ["level_D"], "demo", tmp_path / "results", figure, True)
        assert module.confidence_analysis(trials.drop(columns="confidence"), [], "x", tmp_path, figure, True) is None
    finally:
        sys.modules.pop("_confidence", None)
    table = pd.read_csv(tmp_path / "results" / "demo_confidence.csv")
    assert set(table["correct"]) == {True, False} and {"mean", "ci_low", "ci_high", "flags"} <= set(table.columns)
    assert len(pd.read_csv(tmp_path / "results" / "demo_confidence_auroc.csv")) == 3
    written = json.loads((tmp_path / "results" / "demo_confidence.json").read_text())
    assert written["points"] == payload["points"] == 4 and written["type2_auroc_mean"]["n"] == 3
    assert (tmp_path / "figures" / "demo_confidence.png").stat().st_size > 0
