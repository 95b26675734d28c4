"""A confidence rating after a kind's choice (``response: confidence:``, psyop/protocol/kinds/confidence.py,
psyop/session/confidence.py): which kinds accept it and which refuse it at its line, the scale's keys and text, a
headless simulated session and a window session typed under Xvfb that log ``confidence`` and
``confidence_time_s``, a scale that times out, and the controllers' map (select buttons, then the stick)."""

from __future__ import annotations

import json
import math
import re
import shutil
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pandas as pd
import pytest
from kind_helpers import ScriptedKeys, variant, window_session

from psyop.protocol import load_protocol
from psyop.protocol.kinds import kind_named
from psyop.protocol.kinds.confidence import ConfidenceScale, confidence_text
from psyop.schedule import compile_schedule
from psyop.session.plan import compile_plan

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "protocols" / "examples" / "two_interval_confidence.yaml"
STUDY = "detection_confidence"
SCALE = "  confidence: {points: 4, labels: [guess, unsure, fairly sure, certain]}\n"
MODEL = "  confidence: {criteria: [0.3, 0.9, 1.5]}\n"
#: a protocol of each kind psyop ships, and whether its kind takes a confidence rating
KINDS = {"two_interval": ("protocols/detection.yaml", True), "left_right_nearer": ("protocols/ordinal.yaml", True),
         "pairwise_preference": ("protocols/realism.yaml", True), "yes_no": ("protocols/examples/yes_no.yaml", True),
         "n_afc": ("protocols/examples/n_afc.yaml", True), "with_against": ("protocols/examples/nc_calibration.yaml",
                                                                            True),
         "rating": ("protocols/examples/rating.yaml", False), "adjustment": ("protocols/examples/adjustment.yaml", False),
         "reach": ("protocols/egocentric.yaml", False)}


def _with_confidence(source: Path, tmp_path: Path, name: str, scale: str = SCALE, model: str | None = MODEL) -> Path:
    """``source`` with a confidence scale under response: (and a confidence model under observer:)."""
    text = source.read_text().replace("\nresponse:\n", "\nresponse:\n" + scale, 1)
    if model is not None:
        text = text.replace("\nobserver:", "\nobserver:\n" + model.rstrip("\n") + "\n  # the kind's own model:", 1)
    folder = tmp_path / "protocols"  # beside ../assets, as the shipped protocols name their models
    folder.mkdir(exist_ok=True)
    if not (tmp_path / "assets").exists():
        (tmp_path / "assets").symlink_to(REPO / "assets")
    path = folder / name
    path.write_text(text)
    return path


def _validate(paths: list[Path]) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "psyop", "validate", *map(str, paths)], cwd=REPO,
                          capture_output=True, text=True, timeout=120)


def _line_of(path: Path, starts: str) -> int:
    return next(i for i, text in enumerate(path.read_text().splitlines(), 1) if text.startswith(starts))


def test_every_choice_kind_accepts_a_confidence_scale_and_the_others_refuse_it_at_its_line(tmp_path: Path) -> None:
    paths = {kind: _with_confidence(REPO / source, tmp_path, f"{kind}.yaml") for kind, (source, _) in KINDS.items()}
    for kind, (_, takes) in KINDS.items():
        assert kind_named(kind).takes_confidence is takes, kind
    accepted = [paths[k] for k, (_, takes) in KINDS.items() if takes]
    done = _validate(accepted)
    assert done.returncode == 0, done.stderr
    refused = {k: paths[k] for k, (_, takes) in KINDS.items() if not takes}
    done = _validate(list(refused.values()))
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == len(refused), lines  # one line each
    reasons = {"rating": "already is a rating", "adjustment": "is an adjusted value", "reach": "is a hand position"}
    for kind, path in refused.items():
        (mine,) = [text for text in lines if f"{path.name}:" in text]
        assert f"{path.name}:{_line_of(path, '  confidence:')}:" in mine, mine
        article = "an" if kind[0] in "aeiou" else "a"
        assert f"{article} {kind} response takes no confidence rating: its answer {reasons[kind]}" in mine, mine


def test_a_wrong_scale_or_observer_model_is_refused_with_its_line(tmp_path: Path) -> None:
    bad = {
        "points": (EXAMPLE.read_text().replace("    points: 4 ", "    points: 1 "), "    points:", "has 2 to 9 points"),
        "labels": (EXAMPLE.read_text().replace("    points: 4 ", "    points: 5 ").replace("[0.3, 0.9, 1.5]",
                                                                                        "[0.3, 0.9, 1.5, 2]"),
                   "    labels:",
                   "4 label(s) for a 5-point confidence scale"),
        "criteria": (EXAMPLE.read_text().replace("[0.3, 0.9, 1.5]", "[0.3, 0.9]"), "    criteria:",
                     "2 criteria for a 4-point confidence scale"),
        "order": (EXAMPLE.read_text().replace("[0.3, 0.9, 1.5]", "[0.9, 0.3, 1.5]"), "    criteria:",
                  "must increase strictly"),
        "no_model": (re.sub(r"(?m)^  confidence: +# assumed: psyop.*\n(    .*\n)+", "", EXAMPLE.read_text()), "observer:",
                     "states no confidence model"),
    }
    paths = {}
    for name, (text, starts, message) in bad.items():
        paths[name] = tmp_path / f"bad_{name}.yaml"
        paths[name].write_text(text)
    done = _validate(list(paths.values()))
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == len(bad), lines
    for name, (_, starts, message) in bad.items():
        path = paths[name]
        (mine,) = [text for text in lines if f"{path.name}:" in text]
        assert f"{path.name}:{_line_of(path, starts)}:" in mine and message in mine, mine


def test_an_observer_confidence_model_without_a_scale_is_refused(tmp_path: Path) -> None:
    path = _with_confidence(REPO / "protocols" / "detection.yaml", tmp_path, "model_only.yaml", scale="")
    done = _validate([path])
    assert done.returncode == 2 and "the response asks no confidence" in done.stderr, done.stderr
    assert f"{path.name}:{_line_of(path, '  confidence:')}:" in done.stderr


def test_the_scale_text_names_the_keys_and_labels_under_the_question() -> None:
    scale = load_protocol(EXAMPLE).response.confidence
    assert confidence_text(scale) == "How sure are you?\n\n1  guess\n2  unsure\n3  fairly sure\n4  certain"
    assert confidence_text(ConfidenceScale(points=3)) == "How sure are you?\n\n1 (least sure) to 3 (most sure)"


def _asker(scale: ConfidenceScale, source: object, timeout_s: float | None):
    from psyop.session.clock import VirtualClock
    from psyop.session.confidence import ConfidenceAsker
    from psyop.session.frames import HeadlessDisplay

    clock = VirtualClock()
    clock.sleep_until(10.0)
    asker = ConfidenceAsker(scale, source, clock, HeadlessDisplay(clock, 90.0), timeout_s=timeout_s,
                            every_frame=False, frame_period_s=1 / 90)
    return asker, clock


def test_keys_1_to_k_rate_a_key_pressed_before_the_scale_does_not_and_a_silent_scale_times_out() -> None:
    from psyop.devices.responses.keyboard import KeyboardResponses
    from psyop.session.responses.base import Response

    scale = ConfidenceScale(points=4)
    keys = ScriptedKeys([("1", 9.5), ("5", 10.1), ("left", 10.2), ("KP_3", 10.4), ("2", 10.5)])
    keyboard = KeyboardResponses(keys, kind_named("two_interval"))
    asker, _ = _asker(scale, keyboard, timeout_s=5.0)
    answered = dict(asker.ask({"trial": 0}, Response("1", correct=True), lambda request: None).extras)
    assert answered["confidence"] == 3.0 and math.isclose(answered["confidence_time_s"], 0.4)
    assert answered["confidence_outcome"] == "answered"
    asker, clock = _asker(scale, KeyboardResponses(ScriptedKeys([]), kind_named("two_interval")), timeout_s=2.0)
    timed_out = dict(asker.ask({"trial": 1}, Response("2", correct=False), lambda request: None).extras)
    assert math.isnan(timed_out["confidence"]) and timed_out["confidence_outcome"] == "timeout"
    assert math.isclose(clock.now_s(), 12.0)  # it waited for the response's timeout, not longer
    skipped = dict(asker.ask({"trial": 2}, Response("timeout"), lambda request: None).extras)
    assert skipped["confidence_outcome"] == "not_asked"


def test_a_response_box_rates_with_its_digit_buttons() -> None:
    """The serial box (a pseudo-terminal speaking its line protocol, as tests/devices/test_serial.py): after the
    choice, B9 (off a 4-point scale) and BL (no digit) are ignored and B2 rates 2."""
    from test_serial import PtyDevice

    from psyop.devices.responses.serial_box import SerialResponseBox
    from psyop.session.clock import RealClock
    from psyop.session.confidence import ConfidenceAsker
    from psyop.session.frames import HeadlessDisplay
    from psyop.session.responses.base import Response

    device, clock = PtyDevice(), RealClock()
    kind = kind_named("two_interval")
    box = SerialResponseBox(device.path, kind, clock=clock.now_s, buttons=kind.buttons)
    try:
        asker = ConfidenceAsker(ConfidenceScale(points=4), box, clock, HeadlessDisplay(clock, 90.0), timeout_s=20.0,
                                every_frame=True, frame_period_s=1 / 90)
        drawn: list[float] = []

        def draw(request) -> None:  # the participant presses once the scale's first frame is drawn
            if not drawn:
                device.write(b"B9\nBL\nB2\n")
            drawn.append(request.display_time_s)

        rated = dict(asker.ask({"trial": 0}, Response("1", correct=True), draw).extras)
    finally:
        box.close()
        device.close()
    assert rated["confidence"] == 2.0 and rated["confidence_outcome"] == "answered"
    assert 0.0 <= rated["confidence_time_s"] < 20.0 and len(drawn) >= 1


def test_a_headless_simulated_session_logs_confidence_and_its_time(tmp_path: Path) -> None:
    from psyop.cli import main as psyop_main

    protocol = variant(EXAMPLE, tmp_path, repetitions=4, phase_s=0.05)
    data = tmp_path / "data"
    assert psyop_main(["simulate", "--data", str(data), "--protocols", str(protocol), "--participants", "1"]) == 0
    session = next((data / STUDY).glob("sub-*/ses-1"))
    trials = pd.read_parquet(session / "trials.parquet")
    assert len(trials) == 20 and trials["confidence"].between(1, 4).all()
    assert (trials["confidence"] % 1 == 0).all() and trials["confidence"].nunique() >= 2  # varies between trials
    assert (trials["confidence_outcome"] == "answered").all() and (trials["confidence_time_s"] == 0.0).all()
    assert (trials["confidence_points"] == 4).all()
    # the stated model, recomputed from the observer's own draws: the same ratings
    from psyop.session.responses.simulated import make_observer

    meta = json.loads((session / "session.json").read_text())
    observer = make_observer(compile_plan(load_protocol(protocol)).observer_params(), seed=int(meta["seed"]),
                             participant=str(trials["participant"].iloc[0]))
    expected = [observer.confidence(row, 4) for row in compile_schedule(load_protocol(protocol),
                                                                         int(meta["seed"])).to_dict("records")]
    assert trials.sort_values("trial")["confidence"].astype(int).tolist() == expected


def test_the_controllers_choose_with_the_select_buttons_and_rate_with_the_stick(monkeypatch) -> None:
    import psyop.devices.xr.tracking as tracking
    from psyop.run.backends import BACKENDS
    from psyop.session.scale_picker import picks_on_scale

    (backend,) = [b for b in BACKENDS if b.category == "responses" and b.name == "openxr"]
    monkeypatch.setattr(tracking, "_openxr_display", lambda built, flag: SimpleNamespace(runtime=None))
    plan = compile_plan(load_protocol(EXAMPLE))
    source = backend.make("", SimpleNamespace(plan=plan, display=None))
    assert source.keymap == {**plan.response.inputs.controller, "thumbstick_x": "scale_axis"}
    assert picks_on_scale(source)  # tests/devices/xr/test_openxr_rating.py answers on the real runtime


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs xvfb-run (Debian xvfb)")
def test_a_window_session_typed_under_xvfb_logs_the_choice_and_the_confidence(tmp_path: Path) -> None:
    protocol = variant(EXAMPLE, tmp_path, repetitions=1, phase_s=0.03,
                       replace=(("levels: [0, 0.25, 0.5, 0.75, 1]", "levels: [0.5, 1]"),))
    # every poll types 3 then 1: the choice reads 1 (interval 1; 3 is no choice key), the scale reads 3 first
    assert window_session(protocol, tmp_path / "data", ["3", "1"]) == "complete"
    session = tmp_path / "data" / STUDY / "sub-W1" / "ses-1"
    trials = pd.read_parquet(session / "trials.parquet")
    assert len(trials) == 2 and (trials["response"] == "1").all()
    assert (trials["confidence"] == 3).all() and (trials["confidence_outcome"] == "answered").all()
    assert (trials["confidence_time_s"] >= 0).all()


def test_the_scale_is_drawn_on_the_head_fixed_text_panel() -> None:
    """The confidence phase through the session's renderer (headless EGL): a dark panel with light text straight
    ahead, and the scale's text, not the choice's prompt."""
    import numpy as np

    from psyop.rendering import Renderer
    from psyop.rendering.renderer import create_headless_context
    from psyop.session.scene_renderer import SceneRenderer
    from psyop.stimulus import blank_scene

    plan = compile_plan(load_protocol(EXAMPLE), tracker_ipd_m=0.064)
    asker, _ = _asker(plan.protocol.response.confidence, None, timeout_s=None)
    ctx = create_headless_context()
    renderer = SceneRenderer(plan, scale=0.25, ctx=ctx, owns_ctx=False)
    try:
        images = {}
        for name, phase in (("confidence", asker.phase), ("prompt", plan.response.phase)):
            check = renderer.render({"trial": 0}, phase, "conventional", 0.1, (0.0, 0.0, -1.0))
            assert check.checked and check.ok
            images[name] = renderer._renderer.image("right").copy()
        camera = plan.rig.camera(renderer.display, "right", (0.0, 0.0, -1.0), "conventional")
        with Renderer(blank_scene(), ctx=ctx, settings=renderer.settings) as blank:
            blank.render(camera)
            without = blank.image("right").copy()
    finally:
        renderer.close()
        ctx.release()
    differs = np.any(np.abs(images["confidence"] - without) > 1e-3, axis=2)
    assert 0.0005 < differs.mean() < 0.5  # a panel, not the whole view
    rows, cols = np.nonzero(differs)
    h, w = differs.shape
    assert rows.min() < h / 2 < rows.max() and cols.min() < w / 2 < cols.max()  # straight ahead
    assert (images["confidence"][differs].max(axis=1) > 0.7).mean() > 0.01  # light ink on the panel
    assert np.any(np.abs(images["confidence"] - images["prompt"]) > 1e-3)  # its own text, not the choice's
