"""The ``yes_no`` kind (psyop/protocol/kinds/yes_no.py) end to end: its schedule, what the participant sees on
signal and noise trials, its keys, response-box buttons and controller, a window session typed under Xvfb,
simulated sessions and their analysis (analysis/yes_no.py), recovery of the simulated observer, bad input."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from kind_helpers import (ScriptedKeys, red_near_centre, render_frames, run_analysis, variant,
                          window_session)
from session_helpers import wait_until
from test_serial import PtyDevice

from psyop.protocol import load_protocol
from psyop.protocol.kinds import kind_named
from psyop.schedule import compile_schedule
from psyop.session.plan import compile_plan
from psyop.session.responses.simulated import make_observer

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "protocols" / "examples" / "yes_no.yaml"


def test_signal_is_balanced_within_each_condition_and_picks_the_interval_mode() -> None:
    schedule = compile_schedule(load_protocol(EXAMPLE), 11)
    counts = schedule.groupby("level_D")["signal"].agg(["sum", "count"])
    assert (counts["sum"] * 2 == counts["count"]).all()
    assert (schedule.loc[schedule["signal"], "mode_interval1"] == "ocular").all()
    assert (schedule.loc[~schedule["signal"], "mode_interval1"] == "conventional").all()


def test_a_signal_trial_shows_the_back_disc_and_a_noise_trial_hides_it(tmp_path: Path) -> None:
    """What the participant sees, not what the schedule says: with the eye turned 15 deg, the signal trial (ocular
    parallax) uncovers a crescent of the red back disc beside the noise disc; the noise trial (conventional) shows
    none, at the same level."""
    schedule = compile_schedule(load_protocol(EXAMPLE), 3)
    top = schedule[schedule["level_D"] == schedule["level_D"].max()]
    trials = {signal: int(top.loc[top["signal"] == signal, "trial"].iloc[0]) for signal in (True, False)}
    render_frames(tmp_path, EXAMPLE, 3, [(f"{signal}.png", trial, 1) for signal, trial in trials.items()])
    found = {signal: red_near_centre(tmp_path / f"{signal}.png") for signal in trials}
    assert found[True] >= 10 and found[False] == 0, found


def test_keys_buttons_and_controller_answer_yes_or_no_and_are_scored_against_the_signal() -> None:
    from psyop.devices.responses.keyboard import KeyboardResponses
    from psyop.devices.responses.serial_box import SerialResponseBox
    from psyop.session.clock import RealClock

    kind = kind_named("yes_no")
    keyboard = KeyboardResponses(ScriptedKeys([]), kind)
    assert keyboard.collect({"signal": True}, 1.0) is None
    keyboard.events = ScriptedKeys([("q", 1.1), ("Y", 1.2)])
    answer = keyboard.collect({"signal": True}, 1.3)
    assert (answer.response, answer.correct) == ("yes", True) and math.isclose(answer.response_time_s, 0.2)
    assert keyboard.collect({"signal": True}, 2.0) is None  # the next trial's prompt
    keyboard.events = ScriptedKeys([("n", 2.5)])
    answer = keyboard.collect({"signal": True}, 2.6)
    assert (answer.response, answer.correct) == ("no", False)
    assert kind.controller == {"left": "yes", "right": "no"}

    device, clock = PtyDevice(), RealClock()
    box = SerialResponseBox(device.path, kind, clock=clock.now_s)
    try:
        row = {"signal": False}
        assert box.collect(row, clock.now_s()) is None
        device.write(b"B7\nBN\n")
        answer = wait_until(lambda: box.collect(row, clock.now_s()), what="the box's N button")
        assert (answer.response, answer.correct) == ("no", True)
    finally:
        box.close()
        device.close()


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs xvfb-run (Debian xvfb)")
def test_a_window_session_typed_under_xvfb(tmp_path: Path) -> None:
    protocol = variant(EXAMPLE, tmp_path, repetitions=2, phase_s=0.03)
    assert window_session(protocol, tmp_path / "data", ["y"]) == "complete"
    trials = pd.read_parquet(tmp_path / "data" / "yes_no_detection" / "sub-W1" / "ses-1" / "trials.parquet")
    assert len(trials) == 10 and (trials["response"] == "yes").all()
    assert (trials["correct"] == trials["signal"]).all() and (trials["response_time_s"] >= 0).all()


def test_simulated_sessions_are_analysed_by_make_figures_rules(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                                                ) -> None:
    from psyop.cli import main as psyop_main

    protocol = variant(EXAMPLE, tmp_path, repetitions=10)
    data, results = tmp_path / "data", tmp_path / "results"
    assert psyop_main(["simulate", "--data", str(data), "--protocols", str(protocol), "--participants", "3"]) == 0
    meta = json.loads(next((data / "yes_no_detection").glob("sub-*/ses-1/session.json")).read_text())
    assert meta["response_kind"] == "yes_no" and meta["response"]["level_factor"] == "level_D"
    rules = tmp_path / "studies.mk"
    assert psyop_main(["studies", str(data), "--make-rules", str(rules)]) == 0
    assert "analysis/yes_no.py" in rules.read_text() and "yes_no_detection_yes_no.png" in rules.read_text()
    assert run_analysis(monkeypatch, "yes_no", ["--study", "yes_no_detection", "--data", str(data), "--results",
                                                str(results), "--out", str(tmp_path / "fig.png")]) == 0
    table = pd.read_csv(results / "yes_no_detection_yes_no.csv")
    assert len(table) == 3 * 5 and table["d_prime"].notna().all()
    fits = pd.read_csv(results / "yes_no_detection_yes_no_fits.csv")
    assert len(fits) == 3 and set(fits["participant"]) == {"S01", "S02", "S03"}
    assert (tmp_path / "fig.png").stat().st_size > 0
    summary = json.loads((results / "yes_no_detection.json").read_text())
    assert summary["response_kind"] == "yes_no" and summary["correction"] == "loglinear_all_cells"


def _observed(protocol_path: Path, participants: int, seed: int) -> tuple[pd.DataFrame, dict[str, float]]:
    """Trials answered by the protocol's simulated observer straight from the schedule (no session), and each
    participant's true threshold."""
    protocol = load_protocol(protocol_path)
    params = compile_plan(protocol).observer_params()
    frames, truth = [], {}
    for j in range(participants):
        participant = f"S{j + 1:02d}"
        schedule = compile_schedule(protocol, seed + j)
        observer = make_observer(params, seed=seed + j, participant=participant)
        truth[participant] = observer.participant_state["threshold"]
        answers = [observer.collect(row, 0.0).response for row in schedule.to_dict("records")]
        frames.append(schedule.assign(participant=participant, answer_yes=np.array(answers) == "yes"))
    return pd.concat(frames, ignore_index=True), truth


def test_the_analysis_recovers_the_simulated_observers_threshold_and_d_prime(tmp_path: Path) -> None:
    """Coverage over simulated participants: each one's psychometric "yes" threshold CI (free guess) covers its
    true threshold, and each level's mean d' CI (across participants) covers the observer's d' at that level, at
    a rate a binomial test against 95 % accepts (p > 0.001)."""
    from psyop.statistics.psychometric import fit_psychometric_table, yes_no_options
    from psyop.statistics.signal_detection import rates, summary

    protocol = variant(EXAMPLE, tmp_path, repetitions=80, replace=(("between_subject_sd: 0.05", "between_subject_sd: 0.1"),))
    trials, truth = _observed(protocol, 60, 100)
    fits = fit_psychometric_table(trials[trials["signal"]], "level_D", ["participant"], "answer_yes",
                                  yes_no_options(None, estimate_eta=False, n_bootstrap=50))
    usable = fits[fits["status"].isin(["ok", "no_upper_bound"])]
    assert len(usable) >= 0.85 * len(fits), fits["status"].value_counts()  # 54 of 60 here; the rest flagged
    covered = sum(r["threshold_ci_low_D"] <= truth[r["participant"]] <= r["threshold_ci_high_D"]
                  for r in usable.to_dict("records"))
    print(f"threshold coverage {covered}/{len(usable)}")
    assert stats.binom.cdf(covered, len(usable), 0.95) > 1e-3, (covered, len(usable))

    observer = load_protocol(protocol).observer
    fa, lapse, width = 0.1, 0.02, 0.2
    assert (observer.false_alarm_rate, observer.lapse, observer.width) == (fa, lapse, width)
    hits = 0
    studies = [trials[trials["participant"].isin([f"S{j + 1:02d}" for j in range(k, k + 6)])] for k in range(0, 60, 6)]
    n = 0
    for study in studies:
        means = summary(rates(study, ["level_D"]), ["level_D"])
        for row in means[means["measure"] == "d_prime"].to_dict("records"):
            # the population d' at this level: the mean over participants' thresholds is close to 0.5
            p_hit = fa + (1 - fa - lapse) * stats.norm.cdf((row["level_D"] - 0.5) / width)
            true_d = stats.norm.ppf(p_hit) - stats.norm.ppf(fa)
            hits += row["ci_low"] <= true_d <= row["ci_high"]
            n += 1
    print(f"d' coverage {hits}/{n}")
    assert stats.binom.cdf(hits, n, 0.95) > 1e-3, (hits, n)


def test_signal_equal_to_noise_is_refused_with_its_line(tmp_path: Path) -> None:
    protocol = variant(EXAMPLE, tmp_path, replace=(("noise: {mode: conventional}", "noise: {mode: ocular}"),))
    done = subprocess.run([sys.executable, "-m", "psyop", "validate", str(protocol)], cwd=REPO, capture_output=True,
                          text=True)
    line = next(i for i, text in enumerate(protocol.read_text().splitlines(), 1) if text.startswith("  noise:"))
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert f"yes_no.yaml:{line}:" in done.stderr and "signal and noise are the same stimulus" in done.stderr
