"""The ``rating`` kind (psyop/protocol/kinds/rating.py) end to end: its schedule, what the participant sees in each
rendering mode, its keys, response-box buttons and (no) controller, a window session typed under Xvfb, simulated
sessions and their analysis (analysis/rating.py), recovery of the simulated observer, bad input."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from PIL import Image
from scipy import stats
from kind_helpers import ScriptedKeys, run_analysis, variant, window_session
from session_helpers import wait_until
from test_serial import PtyDevice

from psyop.datacontract import typed_response
from psyop.protocol import load_protocol
from psyop.protocol.kinds import kind_named
from psyop.protocol.kinds.rating import RatingResponse
from psyop.schedule import compile_schedule
from psyop.session.plan import compile_plan
from psyop.session.responses.simulated import make_observer

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "protocols" / "examples" / "rating.yaml"
STUDY = "rating_realism"


def test_the_schedule_balances_the_modes_and_the_interval_shows_the_trials_mode() -> None:
    schedule = compile_schedule(load_protocol(EXAMPLE), 11)
    assert {"mode", "mode_interval1", "scale_points"} <= set(schedule.columns)
    assert schedule["mode"].value_counts().to_dict() == {"conventional": 15, "ocular": 15}
    assert (schedule["mode_interval1"] == schedule["mode"]).all()  # the column the renderer reads
    assert (schedule["scale_points"] == 7).all()


def test_an_ocular_trial_is_rendered_with_ocular_parallax(tmp_path: Path) -> None:
    """What the participant sees, not what the schedule says: an ocular trial's frame (eye turned 15 deg) is the
    frame rendered in ocular mode, and differs from the same trial rendered conventionally."""
    schedule = compile_schedule(load_protocol(EXAMPLE), 3)
    trial = int(schedule.loc[schedule["mode_interval1"] == "ocular", "trial"].iloc[0])
    script = textwrap.dedent(f"""
        from psyop.cli import main
        for name, mode in (("scheduled", None), ("ocular", "ocular"), ("conventional", "conventional")):
            main(["render", {str(EXAMPLE)!r}, "--seed", "3", "--trial", "{trial}", "--interval", "1", "--gaze-deg",
                  "15,0", "--antialiasing", "none", "--out", {str(tmp_path)!r} + f"/{{name}}.png",
                  *(["--mode", mode] if mode else [])])
        """)
    subprocess.run([sys.executable, "-c", script], check=True, cwd=REPO, capture_output=True, timeout=120)
    frame = {name: np.asarray(Image.open(tmp_path / f"{name}.png").convert("RGB")).astype(int)
             for name in ("scheduled", "ocular", "conventional")}
    assert json.loads((tmp_path / "scheduled.png.json").read_text())["mode"] == "ocular"
    assert np.array_equal(frame["scheduled"], frame["ocular"])
    changed = int((frame["scheduled"] != frame["conventional"]).any(axis=2).sum())
    assert changed > 1000, changed


def _response(points: int) -> RatingResponse:
    return RatingResponse.model_validate({"kind": "rating", "stimulus": {"mode": "ocular"},
                                          "scale": {"points": points}})


def test_keys_1_to_k_answer_keys_above_k_are_ignored_and_nothing_is_correct() -> None:
    from psyop.devices.responses.keyboard import KeyboardResponses

    kind = kind_named("rating")
    inputs = kind.inputs(load_protocol(EXAMPLE).response)
    assert set(inputs.keys) == {str(j) for j in range(1, 8)} | {f"kp_{j}" for j in range(1, 8)}
    assert inputs.buttons == {str(j): str(j) for j in range(1, 8)}
    keyboard = KeyboardResponses(ScriptedKeys([]), kind, keymap=inputs.keys)
    assert keyboard.collect({}, 1.0) is None
    keyboard.events = ScriptedKeys([("8", 1.1), ("9", 1.15), ("q", 1.2), ("5", 1.4)])
    answer = keyboard.collect({}, 1.5)
    assert (answer.response, answer.correct) == ("5", None) and math.isclose(answer.response_time_s, 0.4)
    assert typed_response(answer.response)["response_value"] == 5.0
    assert keyboard.collect({}, 2.0) is None
    keyboard.events = ScriptedKeys([("KP_7", 2.2)])
    assert keyboard.collect({}, 2.3).response == "7"
    three = kind.inputs(_response(3))
    assert set(three.keys) == {"1", "2", "3", "kp_1", "kp_2", "kp_3"} and set(three.buttons) == {"1", "2", "3"}
    assert set(kind.inputs(_response(9)).buttons) == {str(j) for j in range(1, 10)}


def test_a_response_box_answers_with_its_digit_buttons_and_the_controllers_with_the_stick(monkeypatch) -> None:
    import psyop.devices.xr.tracking as tracking
    from psyop.devices.responses.serial_box import SerialResponseBox
    from psyop.session.clock import RealClock

    kind = kind_named("rating")
    inputs = kind.inputs(load_protocol(EXAMPLE).response)
    device, clock = PtyDevice(), RealClock()
    box = SerialResponseBox(device.path, kind, clock=clock.now_s, buttons=inputs.buttons)
    try:
        assert box.collect({}, clock.now_s()) is None
        device.write(b"B8\nB9\nBY\nB3\n")
        answer = wait_until(lambda: box.collect({}, clock.now_s()), what="the box's 3 button")
        assert (answer.response, answer.correct) == ("3", None)
        assert box.stats()["garbage"] >= 3  # 8, 9 and Y answer nothing on a 7-point scale
    finally:
        box.close()
        device.close()
    # --responses openxr: the stick's sideways axis moves the highlighted point, a select button confirms it
    # (psyop.session.scale_picker; tests/devices/xr/test_openxr_rating.py answers on the real runtime)
    assert inputs.controller == {"thumbstick_x": "scale_axis", "left": "confirm", "right": "confirm"}
    monkeypatch.setattr(tracking, "_openxr_display", lambda built, flag: SimpleNamespace(runtime=None))
    source = tracking.OpenXRResponses.on_display(None, kind, inputs.controller)
    assert source.keymap == inputs.controller


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs xvfb-run (Debian xvfb)")
def test_a_window_session_typed_under_xvfb(tmp_path: Path) -> None:
    protocol = variant(EXAMPLE, tmp_path, repetitions=2, phase_s=0.03)
    assert window_session(protocol, tmp_path / "data", ["9", "5"]) == "complete"  # 9 is not on the scale
    trials = pd.read_parquet(tmp_path / "data" / STUDY / "sub-W1" / "ses-1" / "trials.parquet")
    assert len(trials) == 4 and (trials["response"] == "5").all() and (trials["response_value"] == 5.0).all()
    assert trials["correct"].isna().all() and (trials["response_time_s"] >= 0).all()


def test_simulated_sessions_are_analysed_by_make_figures_rules(tmp_path: Path, monkeypatch) -> None:
    from psyop.cli import main as psyop_main

    protocol = variant(EXAMPLE, tmp_path, repetitions=6, phase_s=0.2)
    data, results = tmp_path / "data", tmp_path / "results"
    assert psyop_main(["simulate", "--data", str(data), "--protocols", str(protocol), "--participants", "3"]) == 0
    meta = json.loads(next((data / STUDY).glob("sub-*/ses-1/session.json")).read_text())
    assert meta["response_kind"] == "rating"
    rules = tmp_path / "studies.mk"
    assert psyop_main(["studies", str(data), "--make-rules", str(rules)]) == 0
    assert "analysis/rating.py" in rules.read_text() and f"{STUDY}_rating.png" in rules.read_text()
    assert run_analysis(monkeypatch, "rating", ["--study", STUDY, "--data", str(data), "--results", str(results),
                                                "--out", str(tmp_path / "fig.png")]) == 0
    trials = pd.read_parquet(next((data / STUDY).glob("sub-*/ses-1/trials.parquet")))
    assert trials["response_value"].between(1, 7).all() and (trials["response_value"] % 1 == 0).all()
    means = pd.read_csv(results / f"{STUDY}_rating.csv")
    assert sorted(means["mode"]) == ["conventional", "ocular"] and (means["n"] == 3).all()
    assert (means["ci_low"] <= means["mean"]).all() and (means["mean"] <= means["ci_high"]).all()
    model = pd.read_csv(results / f"{STUDY}_rating_model.csv")
    assert "mode=ocular" in set(model["term"]) and (model["part"] == "cut_point").any()
    summary = json.loads((results / f"{STUDY}.json").read_text())
    assert summary["response_kind"] == "rating" and summary["points"] == 7 and len(summary["labels"]) == 7
    assert [row["effect"] for row in summary["anova"]] == ["mode"]
    assert summary["ordinal_model"]["link"] == "probit" and "flags" in summary["ordinal_model"]
    assert (tmp_path / "fig.png").stat().st_size > 0


def _expected_rating(mean: float, sd: float, points: int) -> float:
    """The mean rating of a latent N(mean, sd) cut at 1.5, ..., points - 0.5 (the ends open)."""
    cdf = np.r_[0.0, stats.norm.cdf((np.arange(1.5, points) - mean) / sd), 1.0]
    return float(np.sum(np.arange(1, points + 1) * np.diff(cdf)))


def test_the_analysis_recovers_the_simulated_raters_means_and_mode_effect(tmp_path: Path) -> None:
    """Coverage over simulated studies of 5 participants each (20 trials per mode each): each mode's mean-rating CI
    covers the population's expected rating (exact, from the latent model's category probabilities with the
    participant offsets' variance added), and the ordinal probit model's mode effect CI (participant offsets)
    covers the true latent difference (latent sd 1), at rates a binomial test against 95 % accepts (p > 0.001)."""
    from psyop.statistics.ratings import condition_means, ordinal_model

    protocol_path = variant(EXAMPLE, tmp_path, repetitions=20, replace=(("  sd: 1.2 ", "  sd: 1.0 "),))
    protocol = load_protocol(protocol_path)
    observer = protocol.observer
    assert (observer.sd, observer.between_subject_sd, observer.means) == (1.0, 0.6, {"conventional": 3.6,
                                                                                       "ocular": 4.4})
    params = compile_plan(protocol).observer_params()
    studies, per_study, seed = 60, 5, 500
    frames = []
    for j in range(studies * per_study):
        participant = f"S{j:03d}"
        schedule = compile_schedule(protocol, seed + j)
        rater = make_observer(params, seed=seed + j, participant=participant)
        answers = [rater.collect(row, 0.0).response for row in schedule.to_dict("records")]
        frames.append(schedule.assign(participant=participant, study=j // per_study, rating=np.array(answers, int)))
    trials = pd.concat(frames, ignore_index=True)
    assert trials["rating"].between(1, 7).all() and trials["rating"].nunique() == 7

    total_sd = math.hypot(1.0, 0.6)  # trial noise and participant offset
    truth = {mode: _expected_rating(mean, total_sd, 7) for mode, mean in observer.means.items()}
    covered = n = 0
    for _, study in trials.groupby("study"):
        for row in condition_means(study, ["mode"], points=7).to_dict("records"):
            covered += row["ci_low"] <= truth[row["mode"]] <= row["ci_high"]
            n += 1
    print(f"mean-rating coverage {covered}/{n}")
    assert stats.binom.cdf(covered, n, 0.95) > 1e-3, (covered, n)

    effect, fits = 4.4 - 3.6, 30  # the latent shift in latent sd units (sd 1)
    hits = 0
    for index, study in trials.groupby("study"):
        if index >= fits:
            break
        model = ordinal_model(study, ["mode"], 7, participant_offsets=True)
        assert set(model.flags.split(";")) <= {"", "unused_categories"}, model.flag_text  # an unused end is fine
        row = model.coefficients.set_index("term").loc["mode=ocular"]
        hits += row["ci_low"] <= effect <= row["ci_high"]
    print(f"mode effect coverage {hits}/{fits}")
    assert stats.binom.cdf(hits, fits, 0.95) > 1e-3, (hits, fits)


def test_a_scale_whose_labels_or_points_are_wrong_is_refused_with_its_line(tmp_path: Path) -> None:
    bad = {
        "labels": (variant(EXAMPLE, tmp_path, name="labels.yaml", replace=(("points: 7 ", "points: 6 "),)),
                   "    labels:", "7 label(s) for a 6-point scale"),
        "points": (variant(EXAMPLE, tmp_path, name="points.yaml", replace=(("points: 7 ", "points: 1 "),)),
                   "    points:", "a rating scale has 2 to 9 points"),
        "means": (variant(EXAMPLE, tmp_path, name="means.yaml", replace=(("    ocular: 4.4", ""),)),
                  "  means:", "no mean for mode level 'ocular'"),
    }
    done = subprocess.run([sys.executable, "-m", "psyop", "validate", *(str(p) for p, _, _ in bad.values())],
                          cwd=REPO, capture_output=True, text=True)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == len(bad), lines  # one line each
    for path, starts, message in bad.values():
        line = next(i for i, text in enumerate(path.read_text().splitlines(), 1) if text.startswith(starts))
        (mine,) = [text for text in lines if f"{path.name}:" in text]
        assert f"{path.name}:{line}:" in mine and message in mine, mine
