"""The image observer (``observer: {kind: image}``) answers from the frames it renders: at chance where the two
intervals draw the same frames, more often right at a larger relative depth, a bad parameter refused at its
line, and a whole simulated session is answered by it. Kept cheap: a tenth of the display's
resolution and three frames per interval. Calibration and predictions: benchmarks/bench_image_observer.py."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pandas as pd
import pytest
from scipy.stats import binomtest, fisher_exact

from psyop.errors import UserError
from psyop.protocol import load_protocol, parse_protocol
from psyop.schedule import compile_schedule
from psyop.session.plan import compile_plan
from psyop.session.responses.image_observer import ImageObserverSource, ImageOrdinalSource

DETECTION = Path(__file__).resolve().parents[2] / "protocols" / "detection.yaml"

CHEAP = "  render_scale: 0.1\n  frames_per_interval: 3\n  noise_sd_c2deg2: 1.0e-7\n"
CHEAP_ORDINAL = "  render_scale: 0.1\n  frames_per_interval: 3\n"


def _replace(text: str, old: str, new: str) -> str:
    assert old in text, f"protocols/detection.yaml no longer holds {old!r}"
    return text.replace(old, new)


def image_protocol(test_mode: str = "ocular", observer: str = CHEAP) -> str:
    """protocols/detection.yaml (renamed, back surface at 2 D only) answered by the image observer."""
    text = _replace(DETECTION.read_text(), "  name: detection\n", "  name: image_detection\n")
    text = _replace(text, "test: {mode: ocular}", f"test: {{mode: {test_mode}}}")
    text, n = re.subn(r"(?m)^    back_D:\n      levels: \[1, 2, 3\].*\n", "    back_D:\n      levels: [2]\n", text)
    assert n == 1
    return text[:text.index("\nobserver:")] + "\nobserver:\n  kind: image\n" + observer


def _source(tmp_path: Path, text: str) -> tuple[ImageObserverSource, list[dict]]:
    path = tmp_path / "image_detection.yaml"
    path.write_text(text)
    protocol = load_protocol(path)
    plan = compile_plan(protocol, tracker_ipd_m=0.064)
    params = plan.observer_params()
    assert params is not None
    return ImageObserverSource(params, seed=7, participant="S01", plan=plan), compile_schedule(protocol, 7).to_dict("records")


def test_identical_intervals_answer_at_chance(tmp_path: Path) -> None:
    source, rows = _source(tmp_path, image_protocol(test_mode="conventional"))
    trials = [r for r in rows if r["level_D"] == 1.0][:6] + [r for r in rows if r["level_D"] == 0.5][:6]
    try:
        correct = 0
        for row in trials:
            first, second = source.responses(row)
            assert first == second  # the same frames, the same response: no cue
            correct += bool(source.collect(row, 0.0).correct)
    finally:
        source.close()
    assert binomtest(correct, len(trials), 0.5).pvalue > 0.01, (correct, len(trials))


def test_more_relative_depth_is_answered_right_more_often(tmp_path: Path) -> None:
    source, rows = _source(tmp_path, image_protocol())
    try:
        def correct_at(level_D: float) -> int:
            return sum(bool(source.collect(r, 0.0).correct) for r in [r for r in rows if r["level_D"] == level_D][:8])

        none, most = correct_at(0.0), correct_at(1.0)
    finally:
        source.close()
    # at 0 D the red surface stays hidden in both modes (chance); at 1 D it shows in the ocular interval
    assert most >= 7 and fisher_exact([[most, 8 - most], [none, 8 - none]], alternative="greater").pvalue < 0.05, \
        (none, most)


def test_a_bad_parameter_is_refused_at_its_line() -> None:
    text = image_protocol(observer="  pupil_mm: 0.2\n")
    with pytest.raises(UserError) as info:
        parse_protocol(text, "study.yaml")
    line = next(i for i, t in enumerate(text.splitlines(), 1) if "pupil_mm: 0.2" in t)
    assert info.value.location is not None and info.value.location.startswith(f"study.yaml:{line}:"), str(info.value)
    assert "pupil_mm" in str(info.value) and info.value.exit_code == 2


def test_a_simulated_session_is_answered_by_the_image_observer(tmp_path: Path) -> None:
    from psyop.run.runner import SessionOptions, run_session

    text = _replace(image_protocol(), "levels: [0, 0.25, 0.5, 0.75, 1]", "levels: [0, 1]")
    text = re.sub(r"(?m)^(\s*repetitions:)\s*\d+", r"\g<1> 1", text)
    path = tmp_path / "image_detection.yaml"
    path.write_text(text)
    options = SessionOptions(participant="S01", seed=3, data_root=tmp_path / "data", progress=False,
                             write_description=False, render="cameras")
    outcome = run_session(load_protocol(path), compile_schedule, options)
    assert outcome.status == "complete" and outcome.n_recorded == 2
    session = next((tmp_path / "data").rglob("session.json"))
    record = json.loads(session.read_text())
    assert "responses:sim" in record["simulated_sources"] and "\nobserver:\n  kind: image\n" in record["protocol_text"]
    trials = pd.read_parquet(session.parent / "trials.parquet")
    assert trials["response"].isin(["1", "2"]).all() and trials["correct"].notna().all()
    for _, row in trials.iterrows():  # the decision's values, logged: the answer is the one they give
        values = json.loads(row["observer_responses"])
        assert values["observer"] == "image" and len(values["responses_c2deg2"]) == 2
        assert values["noise_sd_c2deg2"] == 1.0e-7 and bool(row["correct"]) == (values["u"] < values["p"])


def test_only_an_image_observer_s_session_logs_its_decision_values() -> None:
    from psyop.datacontract import OBSERVER_RESPONSES
    from psyop.session.log.schema import trial_schema

    schedule = compile_schedule(load_protocol(DETECTION), 1)
    assert OBSERVER_RESPONSES not in trial_schema(schedule).names
    assert str(trial_schema(schedule, image_observer=True).field(OBSERVER_RESPONSES).type) == "string"


ORDINAL = DETECTION.parent / "ordinal.yaml"


def ordinal_protocol(modes: str = "[conventional, ocular, reversed]", observer: str = CHEAP_ORDINAL) -> str:
    """protocols/ordinal.yaml (renamed, the rendering modes ``modes``) answered by the image observer."""
    text = ORDINAL.read_text().replace("  name: ordinal\n", "  name: image_ordinal\n")
    text = _replace(text, "levels: [conventional, ocular, reversed]", f"levels: {modes}")
    return text[:text.index("\nobserver:")] + "\nobserver:\n  kind: image\n" + observer


def _ordinal_source(tmp_path: Path, text: str) -> tuple[ImageOrdinalSource, list[dict]]:
    path = tmp_path / "image_ordinal.yaml"
    path.write_text(text)
    protocol = load_protocol(path)
    plan = compile_plan(protocol, tracker_ipd_m=0.064)
    params = plan.observer_params()
    assert params is not None
    return ImageOrdinalSource(params, seed=7, participant="S01", plan=plan), compile_schedule(protocol, 7).to_dict("records")


def test_ordinal_without_a_cue_is_answered_at_chance(tmp_path: Path) -> None:
    source, rows = _ordinal_source(tmp_path, ordinal_protocol("[conventional]"))
    try:
        correct = 0
        for row in rows[:16]:
            assert source.evidence_arcmin(row) == [0.0, 0.0]  # the same frames at every fixation: no cue
            answer = source.collect(row, 0.0)
            correct += bool(answer.correct)
            assert json.loads(dict(answer.extras)["observer_responses"])["evidence_arcmin"] == [0.0, 0.0]
    finally:
        source.close()
    assert binomtest(correct, 16, 0.5).pvalue > 0.01, correct


def test_ordinal_ocular_parallax_points_to_the_near_side(tmp_path: Path) -> None:
    # a quarter of the display's resolution: at a tenth the textures' aliasing swamps a few arcmin of shift
    source, rows = _ordinal_source(tmp_path, ordinal_protocol("[ocular]", "  render_scale: 0.25\n  frames_per_interval: 3\n"))
    try:
        trials = [r for r in rows if r["separation_D"] == 2][:6]
        signs = [sum(source.evidence_arcmin(r)) * (1 if r["near_side"] == "left" else -1) for r in trials]
    finally:
        source.close()
    assert sum(s > 0 for s in signs) >= 5, signs  # the evidence says the near side


def test_an_unread_field_is_refused_at_its_line() -> None:
    text = ordinal_protocol(observer="  noise_sd_c2deg2: 1.0e-6\n")
    with pytest.raises(UserError) as info:
        parse_protocol(text, "study.yaml")
    line = next(i for i, t in enumerate(text.splitlines(), 1) if "noise_sd_c2deg2" in t)
    assert info.value.location is not None and info.value.location.startswith(f"study.yaml:{line}:"), str(info.value)
    assert "does not read noise_sd_c2deg2" in str(info.value) and info.value.exit_code == 2


def test_the_half_field_warp_is_scipy_s_linear_shift() -> None:
    """The ordinal rule's bilinear warp equals scipy.ndimage.shift (order 1, edges repeated) to 1e-12."""
    import numpy as np
    from scipy.ndimage import shift

    from psyop.session.image_observer.ordinal import sampled_at_offset

    image = np.random.default_rng(0).random((40, 50, 3))
    for dx, dy in ((0.3, -1.7), (-2.25, 0.5), (7.6, 3.2), (0.0, 0.0)):
        want = shift(image, (-dy, -dx, 0.0), order=1, mode="nearest")
        assert np.max(np.abs(sampled_at_offset(image, dx, dy) - want)) < 1e-12, (dx, dy)
