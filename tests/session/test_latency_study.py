"""protocols/examples/latency_2024.yaml (issue 44 item 4): the 2024 study's latency thresholds (about 43.7 ms at
1.3 D and 21.5 ms at 2.0 D) as a two-interval study over added gaze latency. It runs end to end through simulated
sessions with the latency added per trial, and the psychometric fits recover each simulated participant's
threshold within their 95 % intervals at a rate a binomial test against 95 % accepts."""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd
from kind_helpers import variant
from scipy import stats

from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.session.plan import compile_plan
from psyop.session.responses.simulated import make_observer

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "protocols" / "examples" / "latency_2024.yaml"
PAPER_MS = {1.3: 43.7, 2.0: 21.5}


def test_the_study_runs_with_each_trials_latency_added(tmp_path: Path) -> None:
    from psyop.cli import main

    protocol = variant(EXAMPLE, tmp_path, repetitions=1)
    assert main(["simulate", "--data", str(tmp_path / "data"), "--protocols", str(protocol), "--participants", "1"]) == 0
    session = tmp_path / "data" / "latency_2024" / "sub-S01" / "ses-1"
    trials = pd.read_parquet(session / "trials.parquet")
    frames = pd.read_parquet(session / "frames.parquet")
    added = frames.groupby("trial")["added_latency_s"].max() * 1000.0  # each logged trial's frames carry its latency
    scheduled = trials.set_index("trial")["added_latency_ms"].astype(float).reindex(added.index)
    assert len(added) and ((added - scheduled).abs() < 1e-9).all()
    assert set(trials["response"]) <= {"1", "2"} and len(trials) == 20


def test_the_fits_recover_the_papers_latency_thresholds() -> None:
    from psyop.statistics.psychometric import USABLE_STATUSES, FitOptions, fit_psychometric_table

    protocol = load_protocol(EXAMPLE)
    observer = protocol.observer
    params = compile_plan(protocol).observer_params()
    width, lapse = float(observer.width_D), float(observer.lapse)
    z75 = stats.norm.ppf(0.25 / (0.5 - lapse))  # the curve's 75 % point lies this many widths past its midpoint
    frames, truth = [], {}
    for j in range(24):
        participant = f"S{j + 1:02d}"
        schedule = compile_schedule(protocol, 300 + j)
        answering = make_observer(params, seed=300 + j, participant=participant)
        for separation, paper in PAPER_MS.items():
            truth[(participant, separation)] = paper + answering.participant_state["participant_shift_D"] + z75 * width
        answers = [answering.collect(row, 0.0).correct for row in schedule.to_dict("records")]
        frames.append(schedule.assign(participant=participant, correct=answers))
    fits = fit_psychometric_table(pd.concat(frames), "added_latency_ms", ["participant", "separation_D"], "correct",
                                  FitOptions(n_bootstrap=50, estimate_eta=False))
    usable = fits[fits["status"].isin(USABLE_STATUSES)]
    assert len(usable) >= 0.9 * len(fits), fits["status"].value_counts()
    covered = sum(r["threshold_ci_low_D"] <= truth[(r["participant"], round(r["separation_D"], 1))]
                  <= r["threshold_ci_high_D"] for r in usable.to_dict("records"))
    print(f"latency threshold coverage {covered}/{len(usable)}")
    assert stats.binom.cdf(covered, len(usable), 0.95) > 1e-3, (covered, len(usable))
    means = usable.groupby("separation_D")["threshold_D"].mean()
    for separation, paper in PAPER_MS.items():  # the study's mean over 24 simulated participants
        assert math.isclose(means[separation], paper, abs_tol=4.0), (separation, means[separation])


def test_the_analysis_states_the_reported_thresholds_beside_the_measured_ones(tmp_path: Path, monkeypatch) -> None:
    """``study.reported`` (the paper's 43.7 and 21.5 ms) appears in the thresholds summary beside the mean measured at
    each separation, with its 95 % interval and whether the reported value lies inside it."""
    import json

    from kind_helpers import run_analysis

    from psyop.cli import main

    protocol = variant(EXAMPLE, tmp_path, repetitions=4)
    data, results = tmp_path / "data", tmp_path / "results"
    assert main(["simulate", "--data", str(data), "--protocols", str(protocol), "--participants", "3"]) == 0
    common = ["--study", "latency_2024", "--data", str(data), "--results", str(results)]
    fits = str(results / "latency_2024_fits.csv")
    assert run_analysis(monkeypatch, "fit_psychometric", [*common, "--out", fits]) == 0
    assert run_analysis(monkeypatch, "fig_detection_thresholds", [*common, "--fits", fits,
                                                                  "--out", str(tmp_path / "t.png")]) == 0
    payload = json.loads((results / "latency_2024_thresholds.json").read_text())
    assert [r["threshold"] for r in payload["reported"]] == [43.7, 21.5]
    lines = [v for k, v in payload["summary"].items() if k.startswith("reported threshold at separation_D")]
    assert len(lines) == 2 and all("measured" in line and "95 % CI" in line for line in lines)


def test_a_reported_threshold_must_name_a_condition_of_the_design(tmp_path: Path, capsys) -> None:
    from psyop.cli import main

    for old, new, says in (("{separation_D: 2.0}, threshold: 21.5", "{separation_D: 3.0}, threshold: 21.5",
                            "'3.0' is not a level of separation_D"),
                           ("{separation_D: 2.0}, threshold: 21.5", "{added_latency_ms: 20}, threshold: 21.5",
                            "is the level factor the threshold is measured on")):
        assert main(["validate", str(variant(EXAMPLE, tmp_path, replace=((old, new),)))]) == 2
        err = capsys.readouterr().err
        assert says in err and "latency_2024.yaml:" in err, err
