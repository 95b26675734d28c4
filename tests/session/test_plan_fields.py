"""Every documented protocol field reaches the session through the plan (issue 9, items 1-2).

Each test here failed on the code before the session plan: the field validated and was then
ignored (or crashed the session).
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from session_helpers import PROTOCOLS, small_protocol

from psyop.errors import UserError
from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.session.clock import VirtualClock
from psyop.session.frames import HeadlessDisplay
from psyop.session.loop import LoopConfig, TrialLoop
from psyop.session.plan import TIMEOUT_RESPONSE, compile_plan
from psyop.run.runner import SessionOptions, run_session
from tests.protocol_texts import EGOCENTRIC_BOX_ROOM, EGOCENTRIC_MESH_ROOM

STRAIGHT_AHEAD_M = (0.0315, 0.0, -1.0)


def _variant(tmp_path: Path, study: str, *edits: tuple[str, str], repetitions: int = 1) -> Path:
    path = small_protocol(tmp_path, study, repetitions)
    text = path.read_text()
    for old, new in edits:
        assert old in text, old
        text = text.replace(old, new)
    path.write_text(text)
    return path


def _session_json(root: Path, study: str, participant: str = "P1") -> dict:
    return json.loads((root / study / f"sub-{participant}" / "ses-1" / "session.json").read_text())


def _run(path: Path, root: Path, **options) -> object:
    protocol = load_protocol(path)
    opts = SessionOptions(participant="P1", seed=3, data_root=root, progress=False, fsync=False,
                          render=options.pop("render", "cameras"), **options)
    return run_session(protocol, compile_schedule, opts)


# -- fixed ipd ------------------------------------------------------------------------------
def test_fixed_ipd_is_rendered_and_recorded(tmp_path: Path) -> None:
    path = _variant(tmp_path, "ordinal", ("ipd: tracker", "ipd: {mm: 58}"))
    plan = compile_plan(load_protocol(path))
    assert plan.rig.ipd_m == pytest.approx(0.058) and plan.rig.ipd_source == "protocol"
    np.testing.assert_allclose(plan.rig.centre_m("right"), [0.029, 0.0, 0.0])
    camera = plan.rig.camera(plan.display, "right", (0.029, 0.0, -1.0), "conventional")
    np.testing.assert_allclose(camera.centre_of_projection_m, [0.029, 0.0, 0.0])
    assert _run(path, tmp_path / "data").status == "complete"
    meta = _session_json(tmp_path / "data", "ordinal")
    assert meta["ipd_m"] == pytest.approx(0.058) and meta["rig"]["ipd_source"] == "protocol"


def test_tracker_ipd_without_a_measurement_is_recorded_as_the_default() -> None:
    plan = compile_plan(load_protocol(PROTOCOLS / "ordinal.yaml"))
    assert plan.rig.ipd_m == 0.063 and plan.rig.ipd_source.startswith("default")
    assert compile_plan(load_protocol(PROTOCOLS / "ordinal.yaml"), tracker_ipd_m=0.061).rig.ipd_source == "tracker"


# -- one valid range per quantity -----------------------------------------------------------------
@pytest.mark.parametrize("nc_mm, ok", [(30, False), (29.5, True), (0, False), (7.4, True)])
def test_nc_that_validates_renders(tmp_path: Path, nc_mm: float, ok: bool) -> None:
    path = _variant(tmp_path, "ordinal", ("eye_model: gullstrand_emsley_relaxed", f"eye_model: {{nc_mm: {nc_mm}}}"))
    if not ok:
        with pytest.raises(UserError) as error:
            load_protocol(path)
        assert re.match(rf"{re.escape(str(path))}:\d+:\d+", error.value.location or "")
        return
    plan = compile_plan(load_protocol(path))
    assert plan.rig.nc_m == pytest.approx(nc_mm / 1000)
    for mode in ("conventional", "ocular", "reversed"):
        assert plan.rig.camera(plan.display, "right", (0.3, 0.1, -1.0), mode).valid


@pytest.mark.parametrize("depth, ok", [("{D: 100}", True), ("{m: 0.01}", True), ("{m: 0.005}", False),
                                       ("{D: 101}", False)])
def test_depth_range_is_the_optics_range(tmp_path: Path, depth: str, ok: bool) -> None:
    path = _variant(tmp_path, "discrimination", ("depth: {D: 0}                       # Sec. 5.2", f"depth: {depth}  #"))
    if ok:
        load_protocol(path)
    else:
        with pytest.raises(UserError, match="depth|D|m"):
            load_protocol(path)


# -- unknown adaptive procedures: refused, located (quest_plus and staircase run: tests/adaptive) ---
def test_adaptive_levels_are_refused_with_their_location(tmp_path: Path) -> None:
    text = (PROTOCOLS / "detection.yaml").read_text()
    text, n = re.subn(r"(?m)^      levels: \[0, 0.25, 0.5, 0.75, 1\].*$",
                      "      adaptive: {procedure: quest, start: 0.5, min: 0, max: 1.5}", text)
    assert n == 1
    path = tmp_path / "adaptive.yaml"
    path.write_text(text)
    with pytest.raises(UserError, match="adaptive procedure 'quest' is not available") as error:
        load_protocol(path)
    line = next(i for i, t in enumerate(text.splitlines(), 1) if "procedure: quest" in t)
    assert error.value.location.startswith(f"{path}:{line}:")


# -- blank show / mode / display_off ---------------------------------------------------------------
def test_blank_phase_plan_carries_show_mode_and_display_off(tmp_path: Path) -> None:
    plan = compile_plan(load_protocol(PROTOCOLS / "realism.yaml"))
    blank = next(p for p in plan.phases if p.name == "blank")
    assert blank.primitives == ("grid",) and blank.mode == "conventional" and blank.shows_scene
    path = _variant(tmp_path, "realism", ("      mode: conventional", "      mode: ocular"))
    assert next(p for p in compile_plan(load_protocol(path)).phases if p.name == "blank").mode == "ocular"
    row = {"trial": 0}
    assert plan.mode_for(blank, row) == "conventional"
    off = _variant(tmp_path, "detection", ("    - kind: blank\n", "    - kind: blank\n      display_off: true\n"))
    phase = next(p for p in compile_plan(load_protocol(off)).phases if p.name == "display_off")
    assert phase.show == "off" and not phase.renders


def test_realism_blank_draws_the_grid() -> None:
    from psyop.session.scene_renderer import SceneRenderer

    protocol = load_protocol(PROTOCOLS / "realism.yaml")
    plan = compile_plan(protocol)
    row = compile_schedule(protocol, 1).iloc[0].to_dict()
    blank = next(p for p in plan.phases if p.name == "blank")
    renderer = SceneRenderer(plan, scale=0.25)
    try:
        check = renderer.render(row, blank, plan.mode_for(blank, row), 0.2, STRAIGHT_AHEAD_M)
        image = renderer._renderer.image(renderer.last_eye)
    finally:
        renderer.close()
    assert check.checked and check.ok
    grid = next(item for item in protocol.scene if item.id == "grid")
    assert grid.background_rgb == (0, 0, 0) and grid.rgb == (1, 1, 1)
    # the grid: light lines over its black background, not the plain grey (0.5) blank
    brightness = image.max(axis=2)
    assert (brightness < 0.05).mean() > 0.3 and (brightness > 0.2).mean() > 0.01


# -- drift recalibration target size ----------------------------------------------------------------
def _cross_width_px(target_size_deg: float) -> int:
    from psyop.session.scene_renderer import SceneRenderer

    protocol = load_protocol(PROTOCOLS / "detection.yaml")
    plan = compile_plan(protocol)
    recal = plan.phases[0]
    import dataclasses

    recal = dataclasses.replace(recal, target_size_deg=target_size_deg)
    renderer = SceneRenderer(plan, scale=0.5)
    try:
        renderer.render({"trial": 0, "trial_seed": 1}, recal, "conventional", 0.0, STRAIGHT_AHEAD_M)
        image = renderer._renderer.image(renderer.last_eye)
    finally:
        renderer.close()
    white = np.all(image > 0.6, axis=2)
    columns = np.nonzero(white.any(axis=0))[0]
    return int(columns.max() - columns.min() + 1)


def test_drift_target_size_is_drawn(tmp_path: Path) -> None:
    path = _variant(tmp_path, "detection", ("    - kind: drift_recalibration",
                                            "    - kind: drift_recalibration\n      target_size_deg: 4"))
    assert compile_plan(load_protocol(path)).phases[0].target_size_deg == 4
    small, large = _cross_width_px(2.0), _cross_width_px(8.0)
    assert 3.6 < large / small < 4.4


# -- response timeout, prompt, question ------------------------------------------------------------
class _NeverAnswers:
    needs_images = False

    def __init__(self) -> None:
        self.timeouts = 0

    def collect(self, row, now_s):
        return None

    def timed_out(self) -> None:
        self.timeouts += 1

    def close(self) -> None:
        return None


class _NoStore:
    run_index = 0


def test_response_timeout_is_logged_as_such(tmp_path: Path) -> None:
    path = _variant(tmp_path, "ordinal", ("      expected_s: 1.5                   # assumed",
                                          "      expected_s: 1.5\n      timeout_s: 2.5"))
    protocol = load_protocol(path)
    plan = compile_plan(protocol)
    assert plan.response.timeout_s == 2.5
    from psyop.session.gaze.simulated import SimulatedTracker

    clock, responses, said = VirtualClock(), _NeverAnswers(), []
    loop = TrialLoop(identity={"study": "ordinal", "participant": "P", "session": 1}, phases=plan.phases,
                     clock=clock, gaze=SimulatedTracker(1), responses=responses, renderer=None,
                     display=HeadlessDisplay(clock, 90.0), store=_NoStore(), config=LoopConfig(progress=False, every_frame=False),
                     response=plan.response, announce=said.append)
    row = compile_schedule(protocol, 1).iloc[0].to_dict()
    start = clock.now_s()
    record, _ = loop.run_trial(row)
    assert record["response"] == TIMEOUT_RESPONSE and record["correct"] is None
    assert math.isnan(record["response_time_s"])
    presented = sum(p.duration_s for p in plan.phases)
    assert record["trial_end_s"] - start == pytest.approx(presented + 2.5)
    assert responses.timeouts == 1
    assert said == ["Which surface appeared nearer, left or right?"]


def test_question_and_prompt_are_recorded(tmp_path: Path) -> None:
    path = _variant(tmp_path, "ordinal", ("  kind: left_right_nearer", "  kind: left_right_nearer\n  question: Which side is nearer?"))
    assert _run(path, tmp_path / "data").status == "complete"
    response = _session_json(tmp_path / "data", "ordinal")["response"]
    assert response["question"] == "Which side is nearer?"
    assert response["prompt"] == "Which surface appeared nearer, left or right?"


def test_timeouts_are_left_out_of_the_analysis_and_counted(tmp_path: Path) -> None:
    from psyop.datacontract import drop_timeouts

    trials = pd.DataFrame({"response": ["left", TIMEOUT_RESPONSE, "right"], "correct": [True, None, False]})
    answered = drop_timeouts(trials)
    assert answered["response"].tolist() == ["left", "right"] and answered.attrs["n_timeout_dropped"] == 1


# -- reach rendering levels with any names -------------------------------------------------------------
def test_reach_levels_with_any_names_run(tmp_path: Path) -> None:
    path = _variant(tmp_path, "egocentric",
                    ("levels: [enabled, disabled]", "levels: [with_parallax, without]"),
                    ("modes: {enabled: ocular, disabled: conventional}",
                     "modes: {with_parallax: ocular, without: conventional}"),
                    ("    enabled: {slope", "    with_parallax: {slope"), ("    disabled: {slope", "    without: {slope"))
    assert _run(path, tmp_path / "data", every_frame=True).status == "complete"
    trials = pd.read_parquet(tmp_path / "data" / "egocentric" / "sub-P1" / "ses-1" / "trials.parquet")
    assert set(trials["rendering"]) == {"with_parallax", "without"}
    assert trials["reach_m"].notna().all()


# -- scene fields that were validated and then ignored -------------------------------------------------
def test_room_height_and_table_height_are_built(tmp_path: Path) -> None:
    from psyop.stimulus import build_scene

    # egocentric's room is a mesh now; its former box room with another height and table height
    room = EGOCENTRIC_BOX_ROOM.replace("    height_m: 2.6\n", "    height_m: 3.1\n").replace(
        "table_height_m: 0.75", "table_height_m: 0.9")
    mesh = EGOCENTRIC_MESH_ROOM.replace("../assets/", f"{(PROTOCOLS.parent / 'assets').resolve()}/")  # as copied
    path = _variant(tmp_path, "egocentric", (mesh, room))
    protocol = load_protocol(path)
    row = compile_schedule(protocol, 1).iloc[0].to_dict()
    scene = build_scene(protocol, row, 0.0, (0.03, 0.0, 0.0))
    by_name = {p.name: p for p in scene.primitives}
    eye_height = 1.2
    assert by_name["room_ceiling"].centre_m[1] == pytest.approx(3.1 - eye_height)
    assert by_name["room_table_top"].centre_m[1] == pytest.approx(0.9 - eye_height)


def test_pink_noise_exponent_other_than_one_is_refused(tmp_path: Path) -> None:
    path = _variant(tmp_path, "ordinal", ("left: {kind: one_over_f, exponent: 1,", "left: {kind: one_over_f, exponent: 2,"))
    with pytest.raises(UserError, match="only 1/f"):
        load_protocol(path)


def test_timed_out_trials_end_to_end(tmp_path: Path) -> None:
    """--responses none: every response phase runs to timeout_s; the log says so and the loader
    leaves those trials out of the analysis, counted."""
    from psyop.statistics.dataset import load_dataset

    path = _variant(tmp_path, "ordinal", ("      expected_s: 1.5                   # assumed",
                                          "      expected_s: 1.5\n      timeout_s: 2"))
    plain = tmp_path / "plain"
    plain.mkdir()
    with pytest.raises(UserError, match="timeout_s"):  # nobody answers and nothing ends the wait
        _run(small_protocol(plain, "ordinal"), tmp_path / "refused", responses="none")
    assert _run(path, tmp_path / "data", responses="none").status == "complete"
    trials = pd.read_parquet(tmp_path / "data" / "ordinal" / "sub-P1" / "ses-1" / "trials.parquet")
    assert (trials["response"] == TIMEOUT_RESPONSE).all() and trials["correct"].isna().all()
    assert np.allclose(trials["trial_end_s"] - trials["trial_start_s"],
                       sum(p.duration_s for p in compile_plan(load_protocol(path)).phases) + 2.0)
    loaded = load_dataset(tmp_path / "data", "ordinal")
    assert len(loaded.trials) == 0 and loaded.trials.attrs["n_timeout_dropped"] == len(trials)
    assert len(load_dataset(tmp_path / "data", "ordinal", include_timeouts=True).trials) == len(trials)


def test_a_tracker_ipd_outside_the_range_is_a_user_error() -> None:
    protocol = load_protocol(PROTOCOLS / "ordinal.yaml")
    with pytest.raises(UserError, match="ipd of 0.12"):
        compile_plan(protocol, tracker_ipd_m=0.12)
