"""The ``n_afc`` kind (psyop/protocol/kinds/n_afc.py) end to end: balanced target intervals, what each interval
shows, keys and box buttons 1..n, a window session typed under Xvfb, simulated sessions and their analysis
(analysis/n_afc.py), recovery of the simulated observer's threshold, bad input."""

from __future__ import annotations

import json
import math
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from scipy import stats
from kind_helpers import (ScriptedKeys, red_near_centre, render_frames, run_analysis, variant,
                          window_session)
from session_helpers import wait_until
from test_serial import PtyDevice

from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.session.plan import compile_plan
from psyop.session.responses.simulated import make_observer

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "protocols" / "examples" / "n_afc.yaml"


def test_each_interval_holds_the_target_equally_often_per_condition() -> None:
    schedule = compile_schedule(load_protocol(EXAMPLE), 5)
    table = pd.crosstab(schedule["level_D"], schedule["correct_interval"])
    assert list(table.columns) == [1, 2, 3, 4] and (table.to_numpy() == 4).all()
    for k in range(1, 5):
        target = schedule["correct_interval"] == k
        assert (schedule.loc[target, f"mode_interval{k}"] == "ocular").all()
        assert (schedule.loc[~target, f"mode_interval{k}"] == "conventional").all()


def test_the_target_interval_shows_the_back_disc_and_the_others_hide_it(tmp_path: Path) -> None:
    """Rendered, with the eye turned 15 deg: the target interval (ocular parallax) uncovers the red back disc,
    every other interval of the same trial shows none."""
    schedule = compile_schedule(load_protocol(EXAMPLE), 3)
    row = schedule[schedule["level_D"] == schedule["level_D"].max()].iloc[0]
    render_frames(tmp_path, EXAMPLE, 3, [(f"{k}.png", int(row["trial"]), k) for k in range(1, 5)])
    found = {k: red_near_centre(tmp_path / f"{k}.png") for k in range(1, 5)}
    target = int(row["correct_interval"])
    assert found[target] >= 10 and all(found[k] == 0 for k in found if k != target), (target, found)


def test_keys_and_buttons_one_to_n_answer_and_others_are_ignored() -> None:
    from psyop.devices.responses.keyboard import KeyboardResponses
    from psyop.devices.responses.serial_box import SerialResponseBox
    from psyop.session.clock import RealClock

    plan = compile_plan(load_protocol(EXAMPLE))
    from psyop.protocol.kinds.confidence import SCALE_CONTROLLER

    assert plan.response.inputs.controller == SCALE_CONTROLLER  # the stick picks one of four, a select button confirms
    keyboard = KeyboardResponses(ScriptedKeys([]), plan.kind, keymap=plan.response.inputs.keys)
    row = {"correct_interval": 3}
    assert keyboard.collect(row, 1.0) is None
    keyboard.events = ScriptedKeys([("5", 1.1), ("left", 1.15), ("kp_3", 1.2)])
    answer = keyboard.collect(row, 1.3)
    assert (answer.response, answer.correct) == ("3", True) and math.isclose(answer.response_time_s, 0.2)

    device, clock = PtyDevice(), RealClock()
    box = SerialResponseBox(device.path, plan.kind, clock=clock.now_s, buttons=plan.response.inputs.buttons)
    try:
        assert box.collect(row, clock.now_s()) is None
        device.write(b"B5\nB4\n")
        answer = wait_until(lambda: box.collect(row, clock.now_s()), what="the box's button 4")
        assert (answer.response, answer.correct) == ("4", False)
    finally:
        box.close()
        device.close()


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs xvfb-run (Debian xvfb)")
def test_a_window_session_typed_under_xvfb(tmp_path: Path) -> None:
    protocol = variant(EXAMPLE, tmp_path, repetitions=1, phase_s=0.03)
    assert window_session(protocol, tmp_path / "data", ["3"]) == "complete"
    trials = pd.read_parquet(tmp_path / "data" / "nafc_detection" / "sub-W1" / "ses-1" / "trials.parquet")
    assert len(trials) == 6 and (trials["response"] == "3").all()
    assert (trials["correct"] == (trials["correct_interval"] == 3)).all()


def test_simulated_sessions_are_analysed_by_make_figures_rules(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                                                ) -> None:
    from psyop.cli import main as psyop_main

    protocol = variant(EXAMPLE, tmp_path, repetitions=8)
    data, results = tmp_path / "data", tmp_path / "results"
    assert psyop_main(["simulate", "--data", str(data), "--protocols", str(protocol), "--participants", "3"]) == 0
    rules = tmp_path / "studies.mk"
    assert psyop_main(["studies", str(data), "--make-rules", str(rules)]) == 0
    assert "analysis/n_afc.py" in rules.read_text() and "nafc_detection_n_afc.png" in rules.read_text()
    assert run_analysis(monkeypatch, "n_afc", ["--study", "nafc_detection", "--data", str(data), "--results",
                                               str(results), "--out", str(tmp_path / "fig.png")]) == 0
    fits = pd.read_csv(results / "nafc_detection_n_afc_fits.csv")
    assert len(fits) == 3 and (fits["guess"] == 0.25).all() and (fits["target_p"] == 0.625).all()
    summary = json.loads((results / "nafc_detection.json").read_text())
    assert summary["response_kind"] == "n_afc" and summary["n_alternatives"] == 4


def test_the_fits_recover_each_simulated_participants_threshold(tmp_path: Path) -> None:
    """Each simulated participant's 95 % CI covers the level where its curve reaches (1 + 1/n) / 2 correct, at a
    rate a binomial test against 95 % accepts (p > 0.001)."""
    from psyop.statistics.psychometric import USABLE_STATUSES, fit_psychometric_table, nafc_options

    protocol = load_protocol(variant(EXAMPLE, tmp_path, repetitions=60, replace=(("between_subject_sd: 0.05",
                                                                          "between_subject_sd: 0.1"),)))
    params = compile_plan(protocol).observer_params()
    observer_model = protocol.observer
    frames, truth = [], {}
    g, lapse, width = 0.25, float(observer_model.lapse), float(observer_model.width)
    # the level where p = g + (1 - g) / 2 on the observer's curve (lapse included), from its sigmoid midpoint t
    offset = width * stats.norm.ppf(((1 - g) / 2) / (1 - g - lapse))
    for j in range(60):
        participant = f"S{j + 1:02d}"
        schedule = compile_schedule(protocol, 500 + j)
        observer = make_observer(params, seed=500 + j, participant=participant)
        truth[participant] = observer.participant_state["threshold"] + offset
        answers = [observer.collect(row, 0.0) for row in schedule.to_dict("records")]
        frames.append(schedule.assign(participant=participant, correct=[a.correct for a in answers]))
    trials = pd.concat(frames, ignore_index=True)
    fits = fit_psychometric_table(trials, "level_D", ["participant"], "correct",
                                  nafc_options(4, estimate_eta=False, n_bootstrap=50))
    usable = fits[fits["status"].isin(USABLE_STATUSES)]
    assert len(usable) >= 0.85 * len(fits), fits["status"].value_counts()
    covered = sum(r["threshold_ci_low_D"] <= truth[r["participant"]] <= r["threshold_ci_high_D"]
                  for r in usable.to_dict("records"))
    print(f"threshold coverage {covered}/{len(usable)}")
    assert stats.binom.cdf(covered, len(usable), 0.95) > 1e-3, (covered, len(usable))
    assert trials["correct"].notna().all()


@pytest.mark.parametrize(("old", "new", "says"), [
    ("reference: {mode: conventional}", "reference: {mode: ocular}", "target and reference are the same stimulus"),
    ("alternatives: intervals", "alternatives: locations", "alternatives: locations needs locations_deg with n = 4"),
    ("  n: 4", "  n: 3", "needs 3 interval phase(s)"),
])
def test_bad_input_is_one_line_with_its_place(tmp_path: Path, old: str, new: str, says: str) -> None:
    protocol = variant(EXAMPLE, tmp_path, replace=((old, new),))
    done = subprocess.run([sys.executable, "-m", "psyop", "validate", str(protocol)], cwd=REPO, capture_output=True,
                          text=True)
    assert done.returncode == 2 and "Traceback" not in done.stderr and says in done.stderr, done.stderr
    assert re.search(r"n_afc\.yaml:\d+:\d+", done.stderr), done.stderr
