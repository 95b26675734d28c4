"""Simulated observers: deterministic by seed, and their answers follow their parameters."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from psyop.errors import UserError
from psyop.session.responses.simulated import make_observer

REPO = Path(__file__).resolve().parents[2]


def _rows(n: int, **columns: object) -> list[dict]:
    return [{"trial": i, "trial_seed": 1000 + i, **{k: (v[i] if isinstance(v, (list, np.ndarray)) else v) for k, v in columns.items()}}
            for i in range(n)]


def test_psychometric_answers_follow_the_curve_and_do_not_depend_on_order() -> None:
    params = {"kind": "psychometric_2afc", "level_column": "level_D", "threshold_D": 0.36, "width_D": 0.2, "lapse": 0.02}
    levels = np.tile([0.0, 0.36, 1.0], 1500)
    rows = _rows(levels.size, level_D=levels, correct_interval=np.tile([1, 2], levels.size // 2 + 1)[: levels.size])
    observer = make_observer(params, seed=5, participant="S01")
    answers = [observer.collect(r, 0.0) for r in rows]
    reversed_answers = [make_observer(params, seed=5, participant="S01").collect(r, 0.0) for r in reversed(rows)][::-1]
    assert answers == reversed_answers  # a resumed session answers exactly like an uninterrupted one
    table = pd.DataFrame({"level": levels, "correct": [a.correct for a in answers]})
    pc = table.groupby("level")["correct"].mean()
    assert pc[0.36] == pytest.approx(0.75, abs=0.04)  # threshold_D is the 75 % point
    assert pc[0.0] == pytest.approx(0.5 + 0.48 * 0.0359, abs=0.04)
    assert pc[1.0] == pytest.approx(0.5 + 0.48 * 0.9994, abs=0.03)
    other = [make_observer(params, seed=6, participant="S01").collect(r, 0.0) for r in rows[:200]]
    assert other != answers[:200]


def test_between_subject_threshold_shift_is_per_participant() -> None:
    params = {"kind": "psychometric_2afc", "threshold_D": 0.36, "width_D": 0.2, "between_subject_sd_D": 0.1}
    shifts = [make_observer(params, seed=1, participant=f"S{i:02d}").participant_state["participant_shift_D"]
              for i in range(200)]
    assert np.std(shifts) == pytest.approx(0.1, rel=0.2)
    assert make_observer(params, seed=1, participant="S01").participant_state["participant_shift_D"] == shifts[1]


def test_ordinal_preference_and_reach() -> None:
    ordinal = make_observer({"kind": "ordinal_accuracy", "p_correct": {"ocular": {1.0: 0.667, 2.0: 0.758}}},
                            seed=3, participant="S01")
    rows = _rows(3000, mode="ocular", separation_D=2.0, near_side=np.tile(["left", "right"], 1500))
    assert np.mean([ordinal.collect(r, 0).correct for r in rows]) == pytest.approx(0.758, abs=0.03)
    with pytest.raises(UserError, match="no p_correct"):
        ordinal.collect({**rows[0], "mode": "reversed"}, 0)

    preference = make_observer({"kind": "pairwise_preference", "strength": {"ocular": 3.3, "conventional": 1.0}},
                               seed=3, participant="S01")
    rows = _rows(3000, mode_a="ocular", mode_b="conventional")
    chosen = [preference.collect(r, 0).chosen_mode for r in rows]
    assert np.mean(np.array(chosen) == "ocular") == pytest.approx(3.3 / 4.3, abs=0.03)

    reach = make_observer({"kind": "reach", "arm_reach_m": 0.7, "max_reach_fraction": 1.5, "by_condition": {
        "enabled": {"slope": 1.141, "intercept_m": 0.117, "noise_sd_m": 0.03},
        "disabled": {"slope": 1.128, "intercept_m": 0.116, "noise_sd_m": 0.03}}}, seed=3, participant="S01")
    fractions = np.tile([0.5, 0.58, 0.67, 0.75, 0.82, 0.9], 300)
    rows = _rows(fractions.size, rendering="enabled", target_fraction=fractions)
    responses = [reach.collect(r, 0) for r in rows]
    reaches = np.array([r.reach_m for r in responses])
    slope, intercept = np.polyfit(fractions * 0.7, reaches, 1)
    assert slope == pytest.approx(1.141, abs=0.05) and intercept == pytest.approx(0.117, abs=0.03)
    # the observer reports where its hand truly ends; reach_m is its horizontal distance (straight ahead)
    extras = dict(responses[0].extras)
    hand = np.array([extras["hand_x_m"], extras["hand_y_m"], extras["hand_z_m"]])
    assert -hand[2] == pytest.approx(responses[0].reach_m, abs=1e-9) and hand[1] < 0
    assert extras["arm_reach_m"] == 0.7 and extras["target_m"] == pytest.approx(0.5 * 0.7)


def test_unknown_observer_kind_is_a_user_error() -> None:
    with pytest.raises(UserError, match="unknown kind"):
        make_observer({"kind": "telepathy"}, seed=1, participant="S01")


def test_a_two_interval_observer_takes_a_threshold_offset_per_level_of_a_word_factor(tmp_path: Path) -> None:
    """A mode effect (issue 41 item 2): ``threshold_offset_column: mode`` with ``threshold_offset_D: {ocular: 0,
    reversed: 0.3}``; before, an observer could read only a factor of numbers ("must have numbers as levels here")."""
    from psyop.cli import main
    from psyop.protocol import load_protocol
    from psyop.schedule import compile_schedule
    from psyop.session.plan import compile_plan
    from psyop.session.responses.simulated import make_observer

    text = (REPO / "protocols" / "detection.yaml").read_text()
    for old, new in (("    back_D:\n      levels: [1, 2, 3]                 # Sec. 5.1 Conditions: 1, 2 or 3 D",
                      "    back_D:\n      levels: [1]\n    mode:\n      levels: [ocular, reversed]"),
                     ("  test: {mode: ocular}", "  test: {mode: {factor: mode}}"),
                     ("  threshold_D: 0.36", "  threshold_offset_column: mode\n"
                                             "  threshold_offset_D: {ocular: 0.0, reversed: 0.3}\n  threshold_D: 0.36")):
        assert old in text, old
        text = text.replace(old, new)
    path = tmp_path / "mode_effect.yaml"
    path.write_text(text)
    protocol = load_protocol(path)
    observer = make_observer(compile_plan(protocol).observer_params(), seed=1, participant="S01")
    schedule = compile_schedule(protocol, 1)
    thresholds = {row["mode"]: observer.model.threshold_for(row, observer.participant_state)
                  for row in schedule.to_dict("records")}
    assert thresholds["reversed"] - thresholds["ocular"] == pytest.approx(0.3, abs=1e-12)
    path.write_text(text.replace("{ocular: 0.0, reversed: 0.3}", "{ocular: 0.0}"))
    assert main(["validate", str(path)]) == 2  # a level without its offset is refused at its line


def test_every_kind_declares_its_observers_in_its_own_module() -> None:
    """simulated.py holds no per-kind code: each observer a kind accepts answers through its own module's model
    (``declared``), except the image observer, which has its own response source."""
    from psyop.protocol.image_observer import ImageObserver
    from psyop.protocol.kinds import KINDS
    from psyop.protocol.kinds.base import observer_kind_name
    from psyop.session.responses.simulated import DeclaredObserver, declared_observer

    names = [observer_kind_name(m) for kind in KINDS.values() for m in kind.observer_models if m is not ImageObserver]
    assert {"psychometric_2afc", "ordinal_accuracy", "pairwise_preference", "reach", "nc_nulling"} <= set(names)
    for kind in KINDS.values():
        for model in kind.observer_models:
            assert model.declared is (model is not ImageObserver), model.__name__
            if model.declared:
                assert declared_observer(observer_kind_name(model)) == (kind, model)
    observer = make_observer({"kind": "pairwise_preference", "strength": {"ocular": 2.0, "reversed": 1.0}}, seed=1,
                             participant="S01")
    assert isinstance(observer, DeclaredObserver) and observer.kind.name == "pairwise_preference"


def test_the_simulated_hand_ends_at_the_session_reach_height() -> None:
    """The reach observer's hand height is the one the session measures reaches at (a reach target's default)."""
    from psyop.protocol.kinds.reach import HAND_HEIGHT_M as KIND_HEIGHT_M
    from psyop.session.reach import HAND_HEIGHT_M

    assert KIND_HEIGHT_M == HAND_HEIGHT_M


def test_an_nc_nulling_observer_without_the_rigs_rule_is_a_user_error() -> None:
    params = {"kind": "nc_nulling", "nc_mm": 7.7, "width_mm": 4.0, "eye_model_nc_m": 0.0077}
    with pytest.raises(UserError, match="rendering_nc"):
        make_observer(dict(params, rendering_nc=None), seed=1, participant="S01")
    observer = make_observer(dict(params, rendering_nc={"column": "nc_mm", "column_unit": "mm", "signed": True}),
                             seed=1, participant="S01")
    assert observer.participant_state == {"own_nc_mm": 7.7}
    with pytest.raises(UserError, match="no rendering mode"):
        observer.collect({"trial": 3, "trial_seed": 1, "mode_interval1": "sideways", "nc_mm": 1.0}, 0.0)
