"""The image observer (``observer: {kind: image}``) on ``pairwise_preference`` (the realism study): its depth
evidence follows relative motion along the gaze shifts and not the motion every surface shares (synthetic frames
with known shifts), it prefers at chance where the two intervals render the same frames, a field its rule does not
read is refused at its line, and a simulated session of the realism study is answered by it, each trial's decision
values read back from the finalised trials.parquet. Kept cheap: a tenth of the display's resolution and three or
four frames per interval. Predictions beside the paper's: benchmarks/bench_image_observer.py."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.ndimage import gaussian_filter, shift
from scipy.stats import binomtest

from psyop.errors import UserError
from psyop.optics.angles import fick_direction
from psyop.protocol import parse_protocol
from psyop.schedule import compile_schedule
from psyop.session.image_observer.eye import EyeStage
from psyop.session.image_observer.frames import IntervalFrames
from psyop.session.image_observer.preference import interval_depth_arcmin, p_first_preferred
from psyop.session.plan import compile_plan
from psyop.session.responses.image_choices import ImagePreferenceSource
from psyop.session.responses.image_observer import image_observer_source

REALISM = Path(__file__).resolve().parents[2] / "protocols" / "realism.yaml"
CHEAP = "  render_scale: 0.1\n  frames_per_interval: 4\n"
EYE = EyeStage(pupil_mm=4.0, defocus_D=0.0, mar0_arcmin=1.0, e2_deg=2.5)


def realism_protocol(observer: str = CHEAP) -> str:
    """protocols/realism.yaml (renamed) answered by the image observer."""
    text = REALISM.read_text().replace("  name: realism\n", "  name: image_realism\n")
    return text[:text.index("\nobserver:")] + "\nobserver:\n  kind: image\n" + observer


def _source(text: str) -> tuple[ImagePreferenceSource, list[dict]]:
    protocol = parse_protocol(text, "study.yaml")
    plan = compile_plan(protocol, tracker_ipd_m=0.064)
    params = plan.observer_params()
    assert params is not None
    source = image_observer_source(params, seed=5, participant="S01", plan=plan)
    assert isinstance(source, ImagePreferenceSource)
    return source, compile_schedule(protocol, 5).to_dict("records")


def synthetic_frames(px_per_deg_left: float, px_per_deg_right: float) -> IntervalFrames:
    """Five frames of a smooth grey texture (a 40 deg view, 3 px/deg) seen from gazes 4 deg apart along the
    azimuth: the left half shifts ``px_per_deg_left`` pixels per degree of gaze shift, the right half
    ``px_per_deg_right`` (a surface's ocular parallax per degree follows its depth)."""
    size, half_tan = 120, float(np.tan(np.radians(20.0)))
    texture = gaussian_filter(np.random.default_rng(3).random((size, size)), 2.0)
    texture = 0.5 + 0.4 * (texture - texture.mean()) / np.abs(texture - texture.mean()).max()
    azimuth_deg = np.array([0.0, 4.0, 0.0, -4.0, 0.0])
    images = []
    for az in azimuth_deg:
        left, right = (shift(texture, (0.0, az * rate), order=3, mode="nearest")
                       for rate in (px_per_deg_left, px_per_deg_right))
        image = np.concatenate([left[:, :size // 2], right[:, size // 2:]], axis=1)
        images.append(np.repeat(image[..., None], 3, axis=-1))
    pixel_to_ray = np.array([[2 * half_tan, 0.0, -half_tan], [0.0, -2 * half_tan, half_tan], [0.0, 0.0, -1.0]])
    gaze = np.stack([fick_direction(az, 0.0) for az in azimuth_deg])
    return IntervalFrames(np.stack(images), gaze, pixel_to_ray)


def test_the_evidence_follows_relative_shifts_not_the_shared_one() -> None:
    """Halves shifting by different amounts per degree of gaze shift give evidence in proportion to the difference,
    whichever half moves more (ocular and reversed parallax alike); the same shift everywhere (one depth) gives
    next to none; frames that do not change give none."""
    def evidence(left: float, right: float) -> float:
        return interval_depth_arcmin(synthetic_frames(left, right), EYE, 0.25, 1.0)

    deep, mirrored, shallow, flat = evidence(0.1, 0.4), evidence(0.4, 0.1), evidence(0.2, 0.3), evidence(0.25, 0.25)
    assert evidence(0.0, 0.0) == 0.0
    assert deep > 20.0 * abs(flat), (deep, flat)
    assert mirrored == pytest.approx(deep, rel=0.05) and deep / shallow == pytest.approx(3.0, rel=0.15), \
        (deep, mirrored, shallow)


def test_the_decision_rule_is_a_noisy_comparison() -> None:
    assert p_first_preferred(3.0, 3.0, 1.0, 0.0) == 0.5
    assert p_first_preferred(2.0, 0.0, 1.0, 0.0) == pytest.approx(0.9213503964748575, abs=1e-12)  # Phi(2 / sqrt 2)
    assert p_first_preferred(0.0, 50.0, 1.0, 0.2) == pytest.approx(0.1, abs=1e-12)  # a lapse guesses


def test_identical_intervals_are_preferred_at_chance() -> None:
    """Both intervals rendered conventional (the schedule's modes set alike): the same frames, p = 1/2."""
    source, rows = _source(realism_protocol())
    same = [dict(r, mode_a="conventional", mode_b="conventional", mode_interval1="conventional",
                 mode_interval2="conventional") for r in rows[:16]]
    try:
        first = 0
        for row in same:
            assert source.evidence_arcmin(row) == (0.0, 0.0)
            assert source.decision(row)[1] == 0.5
            first += source.collect(row, 0.0).response == "a"
    finally:
        source.close()
    assert binomtest(first, len(same), 0.5).pvalue > 0.01, first


def test_an_unread_field_is_refused_at_its_line() -> None:
    text = realism_protocol(observer="  criterion_sd: 0.5\n")
    with pytest.raises(UserError) as info:
        parse_protocol(text, "study.yaml")
    line = next(i for i, t in enumerate(text.splitlines(), 1) if t == "  criterion_sd: 0.5")
    assert info.value.location is not None and info.value.location.startswith(f"study.yaml:{line}:"), str(info.value)
    assert "the image observer's preference rule does not read criterion_sd; remove it" in info.value.message
    assert info.value.exit_code == 2


def test_a_realism_session_is_answered_by_the_image_observer(tmp_path: Path) -> None:
    """A simulated session: session.json names the simulated observer (responses:sim, the protocol's kind: image)
    and each trial's decision values come back from trials.parquet, its answer the one they give."""
    from psyop.protocol import load_protocol
    from psyop.run.runner import SessionOptions, run_session

    text = re.sub(r"(?m)^(\s*repetitions:)\s*\d+", r"\g<1> 1", realism_protocol())
    path = tmp_path / "image_realism.yaml"
    path.write_text(text)
    options = SessionOptions(participant="S01", seed=3, data_root=tmp_path / "data", progress=False,
                             write_description=False, render="cameras")
    outcome = run_session(load_protocol(path), compile_schedule, options)
    assert outcome.status == "complete" and outcome.n_recorded == 3
    session = next((tmp_path / "data").rglob("session.json"))
    record = json.loads(session.read_text())
    assert record["simulated"] is True and "responses:sim" in record["simulated_sources"]
    assert "\nobserver:\n  kind: image\n" in record["protocol_text"]
    trials = pd.read_parquet(session.parent / "trials.parquet")
    for _, row in trials.iterrows():
        values = json.loads(row["observer_responses"])
        assert values["observer"] == "image" and values["rule"] == "more depth evidence"
        assert values["modes"] == [row["mode_a"], row["mode_b"]] and len(values["evidence_arcmin"]) == 2
        assert row["response"] == ("a" if values["u"] < values["p"] else "b")
        assert row["chosen_mode"] == values["modes"][0 if row["response"] == "a" else 1]
        if "conventional" in values["modes"]:  # the same frames at every fixation: no evidence
            assert values["evidence_arcmin"][values["modes"].index("conventional")] == 0.0
