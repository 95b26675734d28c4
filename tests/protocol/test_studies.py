"""The paper's five studies load, say where every number comes from, and match the paper."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from psyop.protocol import expand_conditions, load_protocol
from psyop.protocol.display import DISPLAY_PROFILE_NAMES, EYE_MODEL_NAMES
from psyop.schedule import expected_duration_s, trial_count

PROTOCOLS = Path(__file__).resolve().parents[2] / "protocols"
STUDIES = ["detection", "discrimination", "ordinal", "egocentric", "realism"]


@pytest.mark.parametrize("study", STUDIES)
def test_study_loads_with_its_name(study: str) -> None:
    protocol = load_protocol(PROTOCOLS / f"{study}.yaml")
    assert protocol.study.name == study
    assert protocol.source_text == (PROTOCOLS / f"{study}.yaml").read_text()
    assert len(protocol.source_sha256) == 64


@pytest.mark.parametrize("study", STUDIES)
def test_every_number_has_a_comment(study: str) -> None:
    """Each line whose value holds a number carries a comment (its paper section or 'assumed')."""
    missing = []
    for number, line in enumerate((PROTOCOLS / f"{study}.yaml").read_text().splitlines(), 1):
        code = line.split("#", 1)[0]
        value = code.split(":", 1)[1] if ":" in code else code.lstrip(" -")
        if re.search(r"(?<![A-Za-z_])\d", value) and "#" not in line:
            missing.append(f"{number}: {line}")
    assert not missing, "numbers without a source comment:\n" + "\n".join(missing)


@pytest.mark.parametrize("study", STUDIES)
def test_comments_cite_sections_or_say_assumed(study: str) -> None:
    for line in (PROTOCOLS / f"{study}.yaml").read_text().splitlines():
        if "#" in line and re.search(r"\d", line.split("#", 1)[0].split(":", 1)[-1]):
            comment = line.split("#", 1)[1]
            assert re.search(r"Sec\. \d|supplement|assumed|inferred|format version|reference|vertical|a different", comment), line


def _levels(study: str) -> tuple[object, list[dict]]:
    protocol = load_protocol(PROTOCOLS / f"{study}.yaml")
    return protocol, expand_conditions(protocol.design)


def test_detection_matches_section_5_1() -> None:
    protocol, conditions = _levels("detection")
    assert sorted({c["back_D"] for c in conditions}) == [1, 2, 3]
    assert sorted({c["level_D"] for c in conditions}) == [0, 0.25, 0.5, 0.75, 1]
    assert len(conditions) == 15 and trial_count(protocol) == 225
    assert [p.kind for p in protocol.trial.phases] == ["drift_recalibration", "interval", "blank", "interval", "response"]
    assert [getattr(p, "duration_s", None) for p in protocol.trial.phases[1:4]] == [2, 0.5, 2]
    assert protocol.eyes == "right"
    assert protocol.response.test.mode == "ocular" and protocol.response.reference.mode == "conventional"
    fixation = protocol.primitive("fixation")
    assert (fixation.path.eccentricity_deg, fixation.path.speed_deg_s) == (16, 90)
    assert protocol.primitive("back").size_deg == protocol.primitive("front").size_deg == 2
    front = protocol.primitive("front")
    assert front.depth.resolve_D({"back_D": 2, "level_D": 0.25}) == 2.25
    assert protocol.observer.threshold_D == 0.36
    # the paper: "about 25 minutes" including instructions and calibration
    assert 20 * 60 < expected_duration_s(protocol) < 30 * 60


def test_discrimination_matches_section_5_2() -> None:
    protocol, conditions = _levels("discrimination")
    by_offset = {}
    for c in conditions:
        by_offset.setdefault(c["offset_D"], []).append(c["level_D"])
    assert by_offset == {1: [0, 0.45, 0.9, 1.35, 1.8], 2: [0, 0.45, 0.9, 1.35, 1.8], 3: [0, 0.7, 1.4, 2.1, 2.8]}
    assert trial_count(protocol) == 225
    assert protocol.primitive("back").depth.D == 0
    assert protocol.response.test.mode == protocol.response.reference.mode == "ocular"
    assert protocol.response.reference.set == {"level_D": 0}
    observer = protocol.observer
    assert (observer.threshold_D, observer.threshold_slope, observer.threshold_offset_column) == (0.38, 0.11, "offset_D")


def test_ordinal_matches_section_6_1() -> None:
    protocol, conditions = _levels("ordinal")
    assert len(conditions) == 6 and trial_count(protocol) == 90
    border = protocol.primitive("surfaces")
    assert border.far_depth.resolve_D({}) == 0.5
    assert {border.near_depth.resolve_D(c) for c in conditions} == {1.5, 2.5}
    assert protocol.primitive("aperture").diameter_deg == 20
    assert [getattr(p, "duration_s", None) for p in protocol.trial.intervals] == [3]
    assert protocol.observer.p_correct["ocular"][2] == 0.758


def test_egocentric_matches_section_6_2() -> None:
    protocol, conditions = _levels("egocentric")
    assert len(conditions) == 12
    assert sorted({c["target_fraction"] for c in conditions}) == [0.5, 0.58, 0.67, 0.75, 0.82, 0.9]
    assert protocol.design.repetitions == 5 and protocol.design.practice_trials == 2
    assert trial_count(protocol) == 60 + 2
    assert protocol.eyes == "stereo"
    assert protocol.trial.intervals[0].min_duration_s == 5
    # the paper found no condition difference: both conditions use the mean of its two lines (1.141, 1.128)
    assert protocol.observer.by_condition["enabled"].slope == pytest.approx((1.141 + 1.128) / 2)
    assert protocol.observer.by_condition["disabled"].slope == protocol.observer.by_condition["enabled"].slope


def test_realism_matches_section_7() -> None:
    protocol, conditions = _levels("realism")
    assert {c["pair"] for c in conditions} == {"conventional|ocular", "conventional|reversed", "ocular|reversed"}
    field = protocol.primitive("targets")
    assert (field.size_deg, field.field_deg, field.near.D, field.far.D) == (2.6, 60, 3.5, 0.5)
    assert [getattr(p, "duration_s", None) for p in protocol.trial.phases[1:4]] == [3, 1, 3]
    blank = protocol.trial.phases[2]
    assert blank.show == ["grid"] and blank.mode == "conventional"
    assert trial_count(protocol) == 45
    strength = protocol.observer.strength
    assert strength["ocular"] / (strength["ocular"] + strength["conventional"]) == pytest.approx(0.768, abs=0.002)
    assert strength["reversed"] / (strength["reversed"] + strength["conventional"]) == pytest.approx(0.751, abs=0.002)


def test_realism_trial_count_inference() -> None:
    """15 per pair is the smallest count at which 19 participants can show 76.8/75.1/49.1 %."""
    def possible(n: int) -> bool:
        total = 19 * n
        return all(any(round(100 * k / total, 1) == p for k in range(total + 1)) for p in (76.8, 75.1, 49.1))

    assert possible(15)
    assert not any(possible(n) for n in range(1, 15))


def test_name_lists_agree_with_optics() -> None:
    optics_eye = pytest.importorskip("psyop.optics.eye_models")
    optics_display = pytest.importorskip("psyop.optics.display")
    assert set(EYE_MODEL_NAMES) == set(optics_eye.EYE_MODELS)
    assert set(DISPLAY_PROFILE_NAMES) <= set(optics_display.DISPLAY_PROFILES)
    protocol = load_protocol(PROTOCOLS / "detection.yaml")
    from psyop.protocol import resolve_display_profile, resolve_eye_model

    assert resolve_eye_model(protocol.display).nc_mm == pytest.approx(7.6916)
    assert resolve_display_profile(protocol.display).width_px == 1440
