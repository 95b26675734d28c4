"""Each study's reported tests, on trial tables drawn by psyop.statistics.simulate (no sessions)."""

import math
from pathlib import Path

import numpy as np

from psyop.power.study_tests import ordinal_tests, reach_tests, realism_tests, study_tests
from psyop.protocol import load_protocol
from psyop.statistics import simulate

ROOT = Path(__file__).resolve().parents[2]


def test_every_study_kind_reports_its_tests() -> None:
    rng = np.random.default_rng(3)
    ordinal = ordinal_tests(simulate.simulate_ordinal(rng, 6))
    assert [o.test for o in ordinal[:3]] == ["rm-ANOVA: mode", "rm-ANOVA: separation_D", "rm-ANOVA: mode * separation_D"]
    assert len(ordinal) == 3 + 6 and all(0 <= o.p <= 1 for o in ordinal)
    reach = reach_tests(simulate.simulate_reach(rng, 5))
    assert [o.test for o in reach] == ["regression: slope difference", "regression: intercept difference",
                                       "regression: joint difference"]
    realism = realism_tests(simulate.simulate_realism(rng, 5))
    assert realism[0].test == "binomial: ocular over conventional" and realism[0].p < 0.05
    protocol = load_protocol(ROOT / "protocols" / "discrimination.yaml")
    two = study_tests(protocol, simulate.simulate_discrimination(rng, 4, slope=0.5))
    assert [o.test for o in two] == ["rm-ANOVA: threshold ~ offset_D", "regression slope: threshold ~ offset_D"]
    assert two[1].p < 0.05  # a large slope is found


def test_a_test_that_cannot_be_computed_says_why() -> None:
    rng = np.random.default_rng(4)
    protocol = load_protocol(ROOT / "protocols" / "detection.yaml")
    outcomes = study_tests(protocol, simulate.simulate_detection(rng, 1))
    anova = outcomes[0]
    assert math.isnan(anova.p) and anova.note.startswith("not computed:")
