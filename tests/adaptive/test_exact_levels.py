"""Adaptive levels lie exactly on their grids: a staircase's ``min + k * grain``, QUEST+'s declared levels."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from scipy.special import ndtr

from psyop.adaptive.history import Observation
from psyop.adaptive.procedure import make_procedure
from psyop.adaptive.quest_plus import QuestPlusSpec
from psyop.adaptive.staircase import StaircaseSpec
from psyop.adaptive.stopping import StopRule

from tests.adaptive.test_adaptive_session import _run, adaptive_detection

STAIRCASES = [
    StaircaseSpec(start=1.0, min=0.0, max=1.5, up=1, down=2, step_sizes=(0.2, 0.1), stop_reversals=None,
                  stop=StopRule(max_trials=100)),
    StaircaseSpec(start=0.8, min=0.0, max=1.2, up=1, down=3, step_sizes=(0.12, 0.06, 0.03), stop_reversals=None,
                  stop=StopRule(max_trials=100)),
    StaircaseSpec(start=1.0, min=0.1, max=1.3, rule="weighted", target=0.75, step_sizes=(0.1, 0.05),
                  stop_reversals=None, stop=StopRule(max_trials=100)),
    StaircaseSpec(start=0.7, min=0.0, max=1.5, rule="weighted", target=0.7, step_sizes=(0.1, 0.05, 0.025),
                  stop_reversals=None, stop=StopRule(max_trials=100)),
]


def _observer(rng: np.random.Generator, level: float, threshold: float, width: float, lapse: float) -> bool:
    p = 0.5 + (0.5 - lapse) * ndtr((level - threshold) / width)
    return bool(rng.uniform() < p)


def _simulate(spec, runs: int, trials: int, seed: int) -> list[float]:
    procedure = make_procedure(spec)
    rng = np.random.default_rng(seed)
    levels: list[float] = []
    for _ in range(runs):
        threshold, width, lapse = rng.uniform(0.2, 1.0), rng.uniform(0.1, 0.4), rng.uniform(0.0, 0.05)
        history: list[Observation] = []
        for _ in range(trials):
            # a staircase's level is its walk (Staircase.next_level, what state() reports) without the estimate
            level = procedure.next_level(history) if hasattr(procedure, "next_level") else \
                procedure.state(history).next_level
            levels.append(level)
            history.append(Observation(level, _observer(rng, level, threshold, width, lapse)))
    return levels


def test_ten_thousand_staircase_trials_stay_on_the_exact_grid():
    total = 0
    for i, spec in enumerate(STAIRCASES):
        levels = _simulate(spec, runs=25, trials=100, seed=i)
        total += len(levels)
        off = [x for x in levels if not spec.on_grid(x)]
        assert not off, (spec.name, off[:5])
        if spec.rule != "weighted" or spec.target == 0.75:  # a decimal grain: no round-off tail in any repr
            assert all(len(repr(x)) <= 8 for x in levels), sorted({x for x in levels if len(repr(x)) > 8})[:5]
        grid_size = int((Fraction(repr(spec.max)) - Fraction(repr(spec.min))) / spec.grain) + 1
        assert len(set(levels)) <= grid_size
    assert total >= 10_000


def test_the_old_float_walk_would_have_left_the_grid():
    """The check can fail: 0.4 reached by float steps from 1.0 is 0.4000000000000001 (the issue's finding)."""
    spec = STAIRCASES[0]
    assert not spec.on_grid(1.0 - 0.2 - 0.2 - 0.2)
    assert not spec.on_grid(1.0 - 0.2 * 5 + 5.55e-17)
    assert spec.on_grid(0.4) and spec.on_grid(0.0)


def test_quest_plus_presents_only_its_declared_levels():
    spec = QuestPlusSpec.default(0.0, 1.5, stop=StopRule(max_trials=50), stimulus_count=76, threshold_count=76,
                                 first_level=0.51)
    assert 0.3 in spec.stimulus and 0.30000000000000004 not in spec.stimulus  # exact decimals, not np.linspace
    levels = _simulate(spec, runs=40, trials=50, seed=7)
    assert len(levels) == 2000
    assert all(spec.on_grid(x) for x in levels)
    assert levels[0] == 0.51  # the protocol's start, declared, though not a grid point


def test_logged_staircase_levels_are_on_the_grid(tmp_path: Path):
    protocol = adaptive_detection(tmp_path, "{procedure: staircase, rule: 1u3d, start: 1.0, min: 0, max: 1.5, "
                                            "step_sizes: [0.2, 0.1]}", 40, backs="[2]")
    trials = _run(protocol, tmp_path / "data", "G1")
    spec = StaircaseSpec(start=1.0, min=0.0, max=1.5, step_sizes=(0.2, 0.1))
    assert trials["level_D"].map(spec.on_grid).all(), sorted(trials["level_D"].unique())
    assert trials["level_D"].nunique() <= 16


@pytest.mark.parametrize("x", [0.1, 0.25, 1.3, 0.0375])
def test_exact_decimal_round_trips(x):
    from psyop.adaptive.staircase import exact_decimal

    assert float(exact_decimal(x)) == x
