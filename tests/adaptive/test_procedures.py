"""Staircases, QUEST+ convergence, stop rules and interleaving: pure functions of the history."""

import math

import numpy as np
import pytest
from scipy.special import ndtr

from psyop.adaptive import (Interleaved, Observation, QuestPlus, QuestPlusSpec, Staircase, StaircaseSpec,
                            StopRule)


def _run(procedure, threshold, width, lapse, seed, max_trials=500):
    rng = np.random.default_rng(seed)
    history = []
    for _ in range(max_trials):
        state = procedure.state(history)
        if state.finished:
            return state, history
        p = 0.5 + (0.5 - lapse) * ndtr((state.next_level - threshold) / width)
        history.append(Observation(state.next_level, bool(rng.random() < p)))
    return procedure.state(history), history


def test_one_up_three_down_by_hand() -> None:
    spec = StaircaseSpec(start=1.0, min=0.0, max=2.0, up=1, down=3, step_sizes=(0.2, 0.1), stop_reversals=None,
                         discard_reversals=0)
    stair = Staircase(spec)
    levels = []
    history = []
    for correct in [True, True, True, True, True, True, False, True, True, True, False]:
        state = stair.state(history)
        levels.append(round(state.next_level, 10))
        history.append(Observation(state.next_level, correct))
    # 3 correct -> 0.8; 3 correct -> 0.6; wrong -> up (reversal at 0.6) by 0.2 -> 0.8;
    # step now 0.1: 3 correct -> down (reversal at 0.8) -> 0.7; wrong -> up (reversal at 0.7) -> 0.8
    assert levels == [1.0, 1.0, 1.0, 0.8, 0.8, 0.8, 0.6, 0.8, 0.8, 0.8, 0.7]
    final = stair.state(history)
    assert final.next_level == pytest.approx(0.8)
    assert final.reversals == 3
    assert final.step == pytest.approx(0.1)
    assert final.reversal_mean == pytest.approx((0.6 + 0.8 + 0.7) / 3)
    # the logged estimate is the posterior of the threshold given the trials (QUEST+'s model and prior over
    # [min, max]), computed here with a QuestPlus of its own on the staircase's levels
    own = QuestPlus(QuestPlusSpec(stimulus=tuple(round(0.1 * k, 10) for k in range(21)),
                                  threshold=QuestPlusSpec.default(0.0, 2.0).threshold,
                                  width=QuestPlusSpec.default(0.0, 2.0).width))
    mean, sd = own.threshold_estimate(history)
    assert final.estimate_mean == pytest.approx(mean, rel=1e-12) and final.estimate_sd == pytest.approx(sd, rel=1e-12)
    assert final.procedure == "staircase_1u3d"


def test_weighted_steps_and_clamping() -> None:
    spec = StaircaseSpec(start=0.1, min=0.0, max=0.5, rule="weighted", target=0.75, step_sizes=(0.05,),
                         stop_reversals=None)
    stair = Staircase(spec)
    history = [Observation(0.1, True)]
    assert stair.state(history).next_level == pytest.approx(0.05)
    history.append(Observation(0.05, False))  # up by 3 x 0.05
    assert stair.state(history).next_level == pytest.approx(0.2)
    history += [Observation(0.2, False), Observation(0.35, False)]  # 0.35 + 0.15 = 0.5, then clamped
    assert stair.state(history).next_level == pytest.approx(0.5)
    history.append(Observation(0.5, False))
    assert stair.state(history).next_level == pytest.approx(0.5)
    # before any trial: the prior's SD (uniform thresholds over [0, 0.5]), finite
    assert stair.state([]).estimate_sd == pytest.approx(0.5 / math.sqrt(12), rel=0.02)
    assert stair.state([]).estimate_defined


def test_stop_on_reversals_and_on_count() -> None:
    spec = StaircaseSpec(start=1.0, min=0.0, max=2.0, down=2, stop_reversals=6, stop=StopRule(max_trials=400))
    state, history = _run(Staircase(spec), 0.5, 0.2, 0.02, seed=3)
    assert state.finished and state.stop_reason == "reversals" and state.reversals == 6
    assert state.trials == len(history)
    spec = StaircaseSpec(start=1.0, min=0.0, max=2.0, stop_reversals=None, stop=StopRule(max_trials=17))
    state, history = _run(Staircase(spec), 0.5, 0.2, 0.02, seed=3)
    assert state.stop_reason == "max_trials" and len(history) == 17


@pytest.mark.parametrize("threshold,width", [(0.3, 0.1), (1.2, 0.25)])
def test_quest_plus_finds_the_threshold(threshold: float, width: float) -> None:
    spec = QuestPlusSpec.default(0.0, 2.0, stop=StopRule(target_sd=0.06, max_trials=400))
    state, history = _run(QuestPlus(spec), threshold, width, 0.02, seed=11)
    assert state.stop_reason == "target_sd" and state.estimate_sd <= 0.06
    assert abs(state.estimate_mean - threshold) < 4 * 0.06
    assert all(0.0 <= obs.level <= 2.0 for obs in history)


def test_quest_plus_off_grid_levels_count_exactly() -> None:
    q = QuestPlus(QuestPlusSpec.default(0.0, 1.0, stimulus_count=11, threshold_count=21))
    on = q.posterior([Observation(0.5, True)])
    near = q.posterior([Observation(0.5 + 1e-12, True)])
    off = q.posterior([Observation(0.53, True)])
    np.testing.assert_allclose(on, near)
    assert not np.allclose(on, off)


def test_stop_rule_needs_a_criterion() -> None:
    with pytest.raises(ValueError, match="max_trials, target_sd"):
        StopRule()
    assert StopRule(target_sd=0.1, min_trials=5).reason(4, 0.01) == ""
    assert StopRule(target_sd=0.1, min_trials=5).reason(5, 0.01) == "target_sd"
    assert StopRule(target_sd=0.1).reason(50, math.inf) == ""


def test_interleaving_is_a_function_of_the_history() -> None:
    procedures = {f"back_D={b}": Staircase(StaircaseSpec(start=1.0, min=0.0, max=2.0, stop_reversals=None,
                                                         stop=StopRule(max_trials=n)))
                  for b, n in ((1, 8), (2, 12), (3, 5))}
    inter = Interleaved(procedures, seed=42)
    rng = np.random.default_rng(0)
    history = []
    while (step := inter.next(history)).condition is not None:
        history.append((step.condition, Observation(step.state.next_level, bool(rng.random() < 0.7))))
    counts = {c: sum(1 for h in history if h[0] == c) for c in procedures}
    assert counts == {"back_D=1": 8, "back_D=2": 12, "back_D=3": 5}
    # replaying any prefix (a resumed session) gives the same next choice
    for n in range(len(history)):
        step = Interleaved(procedures, seed=42).next(history[:n])
        assert step.condition == history[n][0] and step.state.next_level == history[n][1].level
    assert [h[0] for h in history] != sorted(h[0] for h in history)  # interleaved, not blocked
