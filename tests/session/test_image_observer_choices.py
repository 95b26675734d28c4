"""The image observer (``observer: {kind: image}``) on ``n_afc`` (over intervals) and ``yes_no``: at chance where
the stimuli carry no cue, the n-AFC rule's probabilities equal the two-interval formula at n = 2, the target found
where it moves, and fields a rule does not read or n-AFC over locations refused at their line. Kept cheap: a tenth
of the display's resolution and three frames per interval."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from scipy.stats import binomtest, fisher_exact

from psyop.errors import UserError
from psyop.protocol import parse_protocol
from psyop.schedule import compile_schedule
from psyop.session.image_observer.decisions import p_largest
from psyop.session.plan import compile_plan
from psyop.session.responses.image_choices import ImageIntervalSource, ImageNafcSource, ImageYesNoSource
from psyop.session.responses.image_observer import image_observer_source

EXAMPLES = Path(__file__).resolve().parents[2] / "protocols" / "examples"
CHEAP = "  render_scale: 0.1\n  frames_per_interval: 3\n  noise_sd_c2deg2: 1.0e-7\n"


def _protocol(name: str, old: str, new: str, observer: str = CHEAP) -> str:
    text = (EXAMPLES / f"{name}.yaml").read_text()
    assert old in text, f"protocols/examples/{name}.yaml no longer holds {old!r}"
    text = text.replace(old, new)
    return text[:text.index("\nobserver:")] + "\nobserver:\n  kind: image\n" + observer


def _source(text: str) -> tuple[ImageIntervalSource, list[dict]]:
    protocol = parse_protocol(text, "study.yaml")
    plan = compile_plan(protocol, tracker_ipd_m=0.064)
    params = plan.observer_params()
    assert params is not None
    source = image_observer_source(params, seed=5, participant="S01", plan=plan)
    assert isinstance(source, ImageIntervalSource)
    return source, compile_schedule(protocol, 5).to_dict("records")


def test_the_n_afc_rule_at_two_intervals_is_the_two_interval_formula() -> None:
    for r1, r2, sd in ((1.0, 0.3, 0.5), (0.0, 2.0, 1.5), (4.0, 4.0, 1.0)):
        want = 0.5 * (1.0 + math.erf((r1 - r2) / (sd * math.sqrt(2.0)) / math.sqrt(2.0)))
        assert p_largest((r1, r2), sd, 0.0)[0] == pytest.approx(want, abs=1e-9)
    assert p_largest((1.0, 1.0, 1.0, 1.0), 0.3, 0.1) == pytest.approx([0.25] * 4, abs=1e-12)


def test_n_afc_without_a_cue_is_answered_at_chance() -> None:
    source, rows = _source(_protocol("n_afc", "target: {mode: ocular}", "target: {mode: conventional, set: {level_D: 0}}"))
    assert isinstance(source, ImageNafcSource)
    try:
        correct = 0
        for row in rows[:16]:
            assert len(set(source.responses(row))) == 1  # every interval the same response: no cue
            answer = source.collect(row, 0.0)
            correct += bool(answer.correct)
            values = json.loads(dict(answer.extras)["observer_responses"])  # the decision's values, for the log
            assert values["responses_c2deg2"] == list(source.responses(row)) and values["p"] == pytest.approx(0.25)
    finally:
        source.close()
    assert binomtest(correct, 16, 0.25).pvalue > 0.01, correct


def test_n_afc_finds_the_moving_target() -> None:
    source, rows = _source(_protocol("n_afc", "levels: [0.1, 0.25, 0.4, 0.55, 0.7, 0.85]", "levels: [0.85]"))
    try:
        correct = sum(bool(source.collect(row, 0.0).correct) for row in rows[:6])
    finally:
        source.close()
    assert binomtest(correct, 6, 0.25, alternative="greater").pvalue < 0.01, correct


def test_yes_no_without_a_cue_says_yes_as_often_on_signal_and_noise_trials() -> None:
    source, rows = _source(_protocol("yes_no", "signal: {mode: ocular}", "signal: {mode: conventional, set: {level_D: 0}}"))
    assert isinstance(source, ImageYesNoSource)
    try:
        yes = {True: 0, False: 0}
        trials = [r for r in rows if r["signal"]][:8] + [r for r in rows if not r["signal"]][:8]
        first = source.p_yes(trials[0])
        for row in trials:
            # the same p(yes), signal or noise (to float rounding of the pursued target's pixels): no cue
            assert source.p_yes(row) == pytest.approx(first, abs=1e-6)
            answer = source.collect(row, 0.0)
            yes[bool(row["signal"])] += answer.response == "yes"
            values = json.loads(dict(answer.extras)["observer_responses"])
            assert values["criterion_sd"] == 1.0 and (answer.response == "yes") == (
                (values["u"] < values["p"]) == bool(row["signal"]))
    finally:
        source.close()
    assert fisher_exact([[yes[True], 8 - yes[True]], [yes[False], 8 - yes[False]]]).pvalue > 0.01, yes


@pytest.mark.parametrize("name, old, new, field", [
    ("yes_no", "signal: {mode: ocular}", "signal: {mode: ocular}", "shift_noise_arcmin: 2.0"),
    ("n_afc", "target: {mode: ocular}", "target: {mode: ocular}", "criterion_sd: 0.5"),
])
def test_a_field_the_rule_does_not_read_is_refused_at_its_line(name: str, old: str, new: str, field: str) -> None:
    text = _protocol(name, old, new, observer=f"  {field}\n")
    with pytest.raises(UserError) as info:
        parse_protocol(text, "study.yaml")
    line = next(i for i, t in enumerate(text.splitlines(), 1) if t == f"  {field}")
    assert info.value.location is not None and info.value.location.startswith(f"study.yaml:{line}:"), str(info.value)
    assert f"does not read {field.split(':')[0]}; remove it" in info.value.message


def test_n_afc_over_locations_refuses_the_image_observer_at_its_kind() -> None:
    text = (EXAMPLES / "n_afc_locations.yaml").read_text()
    text = text[:text.index("\nobserver:")] + "\nobserver:\n  kind: image\n"
    with pytest.raises(UserError) as info:
        parse_protocol(text, "study.yaml")
    line = next(i for i, t in enumerate(text.splitlines(), 1) if t == "  kind: image")
    assert info.value.location == f"study.yaml:{line}:9" and "over intervals only" in info.value.message, str(info.value)
