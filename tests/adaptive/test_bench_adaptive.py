"""The efficiency benchmark's vectorised shortcuts equal the session's per-history path (tiny sizes)."""

import numpy as np

from benchmarks.bench_adaptive import observers, posterior_stats, run_constant, run_quest_plus, detection_levels
from psyop.adaptive import Observation, QuestPlus, QuestPlusSpec


def test_batched_quest_plus_and_estimator_match_state() -> None:
    q = QuestPlus(QuestPlusSpec.default(0.0, 2.0, stimulus_count=51, threshold_count=51))
    obs = observers(3, seed=5)
    levels, correct = run_quest_plus(q, obs, 12, np.random.default_rng(0))
    for i in range(3):
        history = [Observation(float(x), bool(c)) for x, c in zip(levels[i], correct[i])]
        for k in range(12):
            assert q.state(history[:k]).next_level == levels[i, k]
    estimator = QuestPlus(QuestPlusSpec.default(0.0, 2.0, stimulus_count=201, threshold_count=51))
    cs_levels, cs_correct = run_constant(detection_levels(), obs, 20, np.random.default_rng(1))
    means, sds = posterior_stats(estimator, cs_levels, cs_correct, np.array([5, 20]))
    for i in range(3):
        for j, n in enumerate((5, 20)):
            state = estimator.state([Observation(float(x), bool(c)) for x, c in zip(cs_levels[i, :n], cs_correct[i, :n])])
            assert np.isclose(means[i, j], state.estimate_mean) and np.isclose(sds[i, j], state.estimate_sd)
