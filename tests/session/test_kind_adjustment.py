"""The ``adjustment`` kind (psyop/protocol/kinds/adjustment.py) end to end: its schedule (seeded starts within the
bounds), bad input refused with its line, what the participant sees as the value changes, its keys and response-box
buttons (raw inputs -> value, path, time), a window session typed under Xvfb (the loop's response phase), simulated
sessions and their analysis (analysis/adjustment.py), and recovery of the simulated observer's bias and sd."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from kind_helpers import ScriptedKeys, variant
from session_helpers import wait_until
from test_serial import PtyDevice

from psyop.protocol import load_protocol
from psyop.protocol.kinds import kind_named
from psyop.protocol.kinds.adjustment import AdjustmentSpec
from psyop.schedule import compile_schedule
from psyop.session.plan import compile_plan
from psyop.session.responses.simulated import make_observer

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "protocols" / "examples" / "adjustment.yaml"
STUDY = "depth_adjustment"


def test_start_values_are_seeded_within_the_bounds_and_the_reference_is_the_factor() -> None:
    protocol = load_protocol(EXAMPLE)
    a, b, c = (compile_schedule(protocol, seed) for seed in (11, 11, 12))
    assert np.array_equal(a["match_D"], b["match_D"]) and not np.array_equal(a["match_D"], c["match_D"])
    assert (a["match_D"] == a["match_D_start"]).all()  # the scene reads the variable's column: the start
    assert a["match_D"].between(0.5, 2.5).all() and a["match_D"].nunique() == len(a)
    assert (a["match_D_reference"] == a["ref_D"]).all() and (a["match_D_path"] == "").all()
    assert (a["adjustment_variable"] == "match_D").all() and (a["mode_interval1"] == a["mode"]).all()
    # the kind's own stream: the design's columns and order do not move with it
    other = compile_schedule(load_protocol(EXAMPLE), 11)
    assert other[["trial", "condition", "trial_seed"]].equals(a[["trial", "condition", "trial_seed"]])


@pytest.mark.parametrize(("old", "new", "key", "message"), [
    ("  field: depth ", "  field: surface.contrast_fraction ", "  field:", "has no field 'surface.contrast_fraction'"),
    ("  field: depth ", "  field: size_deg ", "  field:", "does not read the adjusted variable"),
    ("  item: test ", "  item: tset ", "  item:", "no scene item has id 'tset'"),
    ("  start: {uniform: [0.5, 2.5]}", "  start: {uniform: [0.5, 3.5]}", "  start:", "reaches outside the bounds"),
    ("  start: {uniform: [0.5, 2.5]}", "  start: 4", "  start:", "the start 4 is outside the bounds"),
    ("  bounds: {min: 0.25, max: 3.0}", "  bounds: {min: 3.0, max: 0.25}", "  bounds:", "must be less than max"),
])
def test_bad_input_is_refused_in_one_line_with_its_place(tmp_path: Path, old: str, new: str, key: str,
                                                          message: str) -> None:
    protocol = variant(EXAMPLE, tmp_path, replace=((old, new),))
    done = subprocess.run([sys.executable, "-m", "psyop", "validate", str(protocol)], cwd=REPO, capture_output=True,
                          text=True)
    line = next(i for i, text in enumerate(protocol.read_text().splitlines(), 1) if text.startswith(key))
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert f"adjustment.yaml:{line}:" in done.stderr and message in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr


SIZE_SCENE = (
    ("    surface: {kind: white_noise, grain_deg: 0.1, mean: 0.5, contrast: 1}\n  - id: test",
     "    surface: {kind: solid, rgb: [1, 0, 0]}\n  - id: test"),
    ("    size_deg: 4                         # the same angular size at every depth: size tells no depth\n"
     "    centre_deg: [5, 0]                  # right of straight ahead\n"
     "    depth: {factor: match_D}            # the adjusted variable: the participant's setting, in dioptres\n"
     "    surface: {kind: white_noise, grain_deg: 0.1, mean: 0.5, contrast: 1}",
     "    size_deg: {factor: match_deg}\n    centre_deg: [5, 0]\n    depth: {D: 1}\n"
     "    surface: {kind: solid, rgb: [0, 1, 0]}"),
    ("  variable: match_D ", "  variable: match_deg "), ("  field: depth ", "  field: size_deg "),
    ("  start: {uniform: [0.5, 2.5]}", "  start: {uniform: [2, 3]}"),
    ("  bounds: {min: 0.25, max: 3.0}", "  bounds: {min: 1, max: 8}"),
)


def test_the_response_phase_shows_the_stimulus_at_the_adjusted_value(tmp_path: Path) -> None:
    """What the participant sees while adjusting: the session's renderer draws the response phase (interval 1's
    scene) with the value written into the row. Adjusting the right disc's size from 2 to 6 deg changes only its
    pixels: its area grows by (6/2)^2 (the geometry, within the edge's pixels), its centre stays, the left
    (reference) disc is untouched; the depth example's plan shows the stimulus, not the prompt."""
    from psyop.session.scene_renderer import SceneRenderer

    depth_plan = compile_plan(load_protocol(EXAMPLE), tracker_ipd_m=0.064)
    assert depth_plan.response.phase.show == "stimulus" and depth_plan.response.participant_text is None
    assert depth_plan.response.adjustment == AdjustmentSpec("match_D", 0.25, 3.0, 0.05, 0.5)
    protocol = load_protocol(variant(EXAMPLE, tmp_path, replace=SIZE_SCENE))
    plan = compile_plan(protocol, tracker_ipd_m=0.064)
    row = compile_schedule(protocol, 1).iloc[0].to_dict()
    renderer = SceneRenderer(plan, scale=0.5)
    try:
        images = {}
        for size in (2.0, 6.0):
            check = renderer.render({**row, "match_deg": size}, plan.response.phase, "conventional", 0.1,
                                    (0.032, 0.0, -1.0))
            assert check.ok
            images[size] = renderer._renderer.image(renderer.last_eye).copy()
    finally:
        renderer.close()
    green = {s: (im[..., 1] > 0.7) & (im[..., 0] < 0.3) for s, im in images.items()}
    red = {s: (im[..., 0] > 0.7) & (im[..., 1] < 0.3) for s, im in images.items()}
    assert np.array_equal(red[2.0], red[6.0]) and red[2.0].sum() > 50  # the reference disc: unchanged
    ratio = green[6.0].sum() / green[2.0].sum()
    assert 8.0 < ratio < 10.0, ratio
    centres = {s: np.argwhere(g).mean(axis=0) for s, g in green.items()}
    assert np.abs(centres[6.0] - centres[2.0]).max() < 1.5, centres
    changed = np.argwhere(np.any(images[2.0] != images[6.0], axis=2))
    radius = math.sqrt(green[6.0].sum() / math.pi)  # only the adjusted disc's pixels changed (its edge included)
    assert len(changed) and np.linalg.norm(changed - centres[6.0], axis=1).max() < radius + 2.0


def test_keys_step_the_value_and_confirm_and_keys_before_the_prompt_are_ignored() -> None:
    """What the loop does each frame (psyop.session.loop.TrialLoop._await_adjustment): the keyboard's raw inputs
    since the prompt into the kind's state. Up x3, down x1, Enter: start + 2 steps, a path of 5 entries (the start
    and each press), the time from the prompt; a key pressed before the prompt moves nothing."""
    from psyop.devices.responses.keyboard import KeyboardResponses

    kind = kind_named("adjustment")
    spec = AdjustmentSpec("match_D", 0.25, 3.0, 0.05, 0.5)
    keyboard = KeyboardResponses(ScriptedKeys([("up", 9.5), ("x", 10.1), ("Up", 10.2), ("up", 10.4), ("=", 10.5),
                                        ("down", 10.9)]), kind)
    state = spec.state(1.0, t0_s=10.0)
    for event in keyboard.raw_inputs(10.0, 11.0):
        state.apply(event.name, event.t_s, event.amount)
    assert keyboard.early_presses == 1 and state.confirmed_s is None
    keyboard.events = ScriptedKeys([("return", 11.0), ("enter", 11.25), ("up", 11.3)])
    for event in keyboard.raw_inputs(10.0, 11.5):
        state.apply(event.name, event.t_s, event.amount)
    assert state.confirmed_s == 11.25 and math.isclose(state.confirmed_s - 10.0, 1.25)
    assert state.answer() == repr(1.0 + 2 * 0.05) == "1.1"
    assert [v for _, v in state.path] == [1.0, 1.05, 1.1, 1.15, 1.1] and len(state.path) == 5
    assert json.loads(state.path_json())[1] == [0.2, 1.05]
    # the bounds stop the value; each press is still on the path
    low = spec.state(0.3, t0_s=0.0)
    for t in (0.1, 0.2):
        low.apply("down", t)
    assert low.value == 0.25 and len(low.path) == 3
    assert kind.controller == {"thumbstick": "axis", "left": "confirm", "right": "confirm"}
    assert kind.inputs(load_protocol(EXAMPLE).response).keys["kp_enter"] == "confirm"


def test_response_box_buttons_adjust_over_a_real_pty() -> None:
    from psyop.devices.responses.serial_box import SerialResponseBox
    from psyop.session.clock import RealClock

    kind = kind_named("adjustment")
    device, clock = PtyDevice(), RealClock()
    box = SerialResponseBox(device.path, kind, clock=clock.now_s)
    try:
        device.write(b"BU\n")  # before the prompt: dropped
        wait_until(lambda: box._presses.qsize() == 1 or None, what="the early press")
        prompt_s = clock.now_s()
        spec = AdjustmentSpec("match_D", 0.25, 3.0, 0.05, 0.5)
        state = spec.state(2.0, t0_s=prompt_s)
        device.write(b"BU\nB1\nB7\nBD\nBC\n")
        events: list = []
        wait_until(lambda: events.extend(box.raw_inputs(prompt_s, clock.now_s())) or
                   (len(events) >= 4 or None), what="the box's four buttons")
        for event in events:
            state.apply(event.name, event.t_s, event.amount)
        assert [e.name for e in events] == ["up", "up", "down", "confirm"]
        assert state.confirmed_s is not None and state.confirmed_s >= prompt_s
        assert state.answer() == "2.05" and len(state.path) == 4
    finally:
        box.close()
        device.close()


def test_the_thumbstick_mapping_moves_continuously_at_rate_times_deflection() -> None:
    """The controller's mapping logic without a runtime (on Monado: tests/devices/xr/test_openxr_thumbstick.py): an axis input
    sets the deflection from its time on; the value moves at rate_per_s x deflection, a rest inside the dead zone
    moves nothing, the bounds stop it and a frame's value is carried to its display time."""
    spec = AdjustmentSpec("match_D", 0.0, 2.0, 0.05, 0.5)
    state = spec.state(1.0, t0_s=0.0)
    state.apply("axis", 0.0, 0.05)  # resting: inside the dead zone
    state.apply("axis", 1.0, -0.5)
    assert state.value == 1.0 and math.isclose(state.value_at(2.0), 0.75)
    state.apply("axis", 2.0, 1.0)
    assert math.isclose(state.value, 0.75) and math.isclose(state.value_at(3.0), 1.25)
    state.apply("axis", 10.0, 0.0)
    assert state.value == 2.0  # the upper bound
    state.apply("confirm", 11.0)
    assert state.value_at(20.0) == 2.0 and [round(v, 9) for _, v in state.path] == [1.0, 0.75, 2.0]


WINDOW_SCRIPT = textwrap.dedent(
    """
    from pathlib import Path
    from psyop.protocol import load_protocol
    from psyop.schedule import compile_schedule
    from psyop.run.runner import SessionOptions, run_session
    import psyop.devices.window as window

    typed = window.GlfwWindow.poll
    presses = ["up", "up", "up", "down", "enter"]
    count = [0]
    def poll(self):  # a participant who presses up, up, up, down, Enter: one key per frame
        self.inject_key(presses[count[0] % len(presses)])
        count[0] += 1
        return typed(self)
    window.GlfwWindow.poll = poll
    outcome = run_session(load_protocol(Path({protocol!r})), compile_schedule, SessionOptions(
        participant="W1", data_root=Path({data!r}), clock="real", display="window", responses="keyboard",
        tracker="sim", progress=False, render="auto", window_scale=0.08))
    print(outcome.status, count[0])
    """
)


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs xvfb-run (Debian xvfb)")
def test_a_window_session_typed_under_xvfb(tmp_path: Path) -> None:
    """The loop's response phase with a person's keys: each trial ends start + 2 steps (up x3, down, Enter), its
    path has 5 entries, its time is from the prompt, and the response phase's frames were drawn."""
    protocol = variant(EXAMPLE, tmp_path, repetitions=1, phase_s=0.03)
    script = WINDOW_SCRIPT.format(protocol=str(protocol), data=str(tmp_path / "data"))
    result = subprocess.run(["xvfb-run", "-a", sys.executable, "-c", script], capture_output=True, text=True,
                            timeout=180)
    assert result.returncode == 0 and result.stdout.split()[-2] == "complete", result.stderr[-2000:]
    session = tmp_path / "data" / STUDY / "sub-W1" / "ses-1"
    trials = pd.read_parquet(session / "trials.parquet")
    assert len(trials) == 4
    assert np.allclose(trials["response_value"], trials["match_D_start"] + 2 * 0.05)
    paths = [json.loads(p) for p in trials["match_D_path"]]
    assert all(len(p) == 5 and p[0] == [0.0, start] for p, start in zip(paths, trials["match_D_start"]))
    assert all(np.all(np.diff([t for t, _ in p]) >= 0) for p in paths)
    assert (trials["response_time_s"] >= 0).all() and (trials["response_time_s"] < 10).all()
    assert all(p[-1][0] <= rt + 1e-9 for p, rt in zip(paths, trials["response_time_s"]))
    frames = pd.read_parquet(session / "frames.parquet")
    assert (frames["phase"] == "response").sum() >= 4 * 4  # a frame per key at least: the stimulus was drawn
    meta = json.loads((session / "session.json").read_text())
    assert meta["response"]["adjustment"] == {"variable": "match_D", "bounds": [0.25, 3.0], "step": 0.05,
                                              "rate_per_s": 0.5}


def test_simulated_sessions_are_analysed_by_make_figures_rules(tmp_path: Path) -> None:
    protocol = variant(EXAMPLE, tmp_path, repetitions=4)
    data, results = tmp_path / "data", tmp_path / "results"
    subprocess.run([sys.executable, "-m", "psyop", "simulate", "--data", str(data), "--protocols", str(protocol),
                    "--participants", "3"], check=True, cwd=REPO, capture_output=True)
    trials = pd.read_parquet(next((data / STUDY).glob("sub-S01/ses-1/trials.parquet")))
    path = json.loads(trials["match_D_path"].iloc[0])
    assert path[0][1] == trials["match_D_start"].iloc[0] and path[-1][1] == trials["response_value"].iloc[0]
    assert trials["response_value"].between(0.25, 3.0).all() and trials["correct"].isna().all()
    rules = tmp_path / "studies.mk"
    subprocess.run([sys.executable, "-m", "psyop", "studies", str(data), "--make-rules", str(rules)], check=True,
                   cwd=REPO, capture_output=True)
    assert "analysis/adjustment.py" in rules.read_text() and f"{STUDY}_adjustment.png" in rules.read_text()
    done = subprocess.run([sys.executable, "analysis/adjustment.py", "--study", STUDY, "--data", str(data),
                           "--results", str(results), "--out", str(tmp_path / "fig.png")], cwd=REPO,
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    table = pd.read_csv(results / f"{STUDY}_adjustment.csv")
    assert len(table) == 3 * 4 and table[["pse", "bias", "sd"]].notna().all().all()
    summary = json.loads((results / f"{STUDY}.json").read_text())
    assert summary["response_kind"] == "adjustment" and summary["variable"] == "match_D"
    assert {r["effect"] for r in summary["anova"]} == {"mode", "ref_D", "mode * ref_D"}
    assert (tmp_path / "fig.png").stat().st_size > 0


def _observed(protocol_path: Path, participants: int, seed: int) -> tuple[pd.DataFrame, dict[str, float]]:
    """Trials answered by the protocol's simulated observer straight from the schedule (no session), and each
    participant's true offset."""
    protocol = load_protocol(protocol_path)
    params = compile_plan(protocol).observer_params()
    frames, truth = [], {}
    for j in range(participants):
        participant = f"S{j + 1:02d}"
        schedule = compile_schedule(protocol, seed + j)
        observer = make_observer(params, seed=seed + j, participant=participant)
        truth[participant] = observer.participant_state["offset"]
        finals = [float(observer.collect(row, 0.0).response) for row in schedule.to_dict("records")]
        frames.append(schedule.assign(participant=participant, final_value=finals,
                                      reference_value=schedule["match_D_reference"]))
    return pd.concat(frames, ignore_index=True), truth


def test_the_analysis_recovers_the_observers_bias_and_sd() -> None:
    """Coverage over simulated participants (seed 500, 200 participants, 8 settings per condition): each
    participant x condition's t interval of the bias covers its true bias (the mode's bias + its offset), and the
    c4-corrected SD's chi-square interval covers the observer's sd, at rates a binomial test against 95 % accepts
    (p > 0.001); across 20 studies of 10 participants, the mean bias's interval covers the mode's bias likewise."""
    from psyop.statistics.adjustment import c4, pse_by_participant, summary

    trials, truth = _observed(EXAMPLE, 200, 500)
    bias, sd = {"conventional": 0.1, "ocular": 0.0}, 0.2
    table = pse_by_participant(trials, ["mode", "ref_D"])
    n = table["n"].to_numpy(float)
    true_bias = np.array([bias[m] + truth[p] for m, p in zip(table["mode"], table["participant"])])
    half = stats.t.ppf(0.975, n - 1) * table["sd"].to_numpy() / np.sqrt(n)
    covered = int((np.abs(table["bias"].to_numpy() - true_bias) <= half).sum())
    # sigma's 95 % interval from the chi-square law of (n - 1) s^2 / sigma^2
    s = table["sd"].to_numpy()
    low, high = s * np.sqrt((n - 1) / stats.chi2.ppf(0.975, n - 1)), s * np.sqrt((n - 1) / stats.chi2.ppf(0.025, n - 1))
    sd_covered = int(((low <= sd) & (sd <= high)).sum())
    print(f"bias coverage {covered}/{len(table)}, sd coverage {sd_covered}/{len(table)}")
    assert stats.binom.cdf(covered, len(table), 0.95) > 1e-3 and stats.binom.sf(covered - 1, len(table), 0.95) > 1e-3
    assert stats.binom.cdf(sd_covered, len(table), 0.95) > 1e-3
    # the mean SD over participants estimates c4(n) sd; divided by c4 it is sd (within its own error)
    assert abs(np.mean(s / np.array([c4(int(k)) for k in n])) - sd) < 3 * np.std(s) / np.sqrt(len(s)) + 1e-3
    hits = cells = 0
    for k in range(0, 200, 10):
        part = table[table["participant"].isin([f"S{j + 1:02d}" for j in range(k, k + 10)])]
        means = summary(part, ["mode", "ref_D"], with_anova=False).table
        for row in means[means["measure"] == "bias"].to_dict("records"):
            # the population bias: the mode's (participants' offsets have mean 0)
            hits += row["ci_low"] <= bias[row["mode"]] <= row["ci_high"]
            cells += 1
    print(f"mean-bias coverage {hits}/{cells}")
    assert stats.binom.cdf(hits, cells, 0.95) > 1e-3
