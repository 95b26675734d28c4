"""psyop's vectorised QUEST+ against the `questplus` package on a fixed history."""

import numpy as np
import pytest

from psyop.adaptive import Observation, QuestPlus, QuestPlusSpec

questplus = pytest.importorskip("questplus")

STIM = np.round(np.linspace(0, 1.5, 31), 10)
THRESHOLD = np.round(np.linspace(0, 1.5, 16), 10)
WIDTH = np.array([0.1, 0.2, 0.4])
LAPSE = np.array([0.0, 0.02, 0.04])
HISTORY = [(0.75, True), (0.3, False), (1.2, True), (0.5, True), (0.4, False), (0.6, True),
           (0.55, True), (0.45, False), (0.9, True), (0.35, True), (0.0, False), (1.5, True)]


def _package() -> "questplus.QuestPlus":
    q = questplus.QuestPlus(
        stim_domain={"intensity": STIM},
        param_domain={"mean": THRESHOLD, "sd": WIDTH, "lower_asymptote": 0.5, "lapse_rate": LAPSE},
        outcome_domain={"response": ["Correct", "Incorrect"]}, func="norm_cdf", stim_scale="linear")
    return q


@pytest.mark.parametrize("n_trials", [0, 1, 5, len(HISTORY)])
def test_same_posterior_and_next_stimulus(n_trials: int) -> None:
    ours = QuestPlus(QuestPlusSpec(stimulus=STIM, threshold=THRESHOLD, width=WIDTH, lapse=LAPSE))
    theirs = _package()
    history = [Observation(level, correct) for level, correct in HISTORY[:n_trials]]
    for obs in history:
        theirs.update(stim={"intensity": obs.level}, outcome={"response": "Correct" if obs.correct else "Incorrect"})
    # the package's posterior dims: (mean, sd, lower_asymptote, lapse_rate)
    expected = theirs.posterior.transpose("mean", "sd", "lower_asymptote", "lapse_rate").values[:, :, 0, :]
    np.testing.assert_allclose(ours.posterior(history), expected, rtol=1e-9, atol=1e-15)
    state = ours.state(history)
    assert state.next_level == pytest.approx(theirs.next_stim["intensity"])
    np.testing.assert_allclose(state.estimate_mean, theirs.param_estimate["mean"], rtol=1e-9)
    np.testing.assert_allclose(ours.parameter_means(history)["width"], theirs.param_estimate["sd"], rtol=1e-9)
    np.testing.assert_allclose(ours.parameter_means(history)["lapse"], theirs.param_estimate["lapse_rate"],
                               rtol=1e-9, atol=1e-15)
    assert ours.state(history).trials == n_trials


def test_expected_entropy_matches_direct_formula() -> None:
    """The three-matvec form equals the textbook sum over outcomes of pk * H(posterior | outcome)."""
    q = QuestPlus(QuestPlusSpec(stimulus=STIM, threshold=THRESHOLD, width=WIDTH, lapse=LAPSE))
    history = [Observation(level, correct) for level, correct in HISTORY]
    post = q.posterior(history).ravel()
    direct = []
    for x in STIM:
        pc = 0.5 + (0.5 - q._l) * __import__("scipy").special.ndtr((x - q._t) / q._w)
        eh = 0.0
        for like in (pc, 1 - pc):
            joint = post * like
            pk = joint.sum()
            new = joint / pk
            eh += pk * -np.sum(new[new > 0] * np.log(new[new > 0]))
        direct.append(eh)
    np.testing.assert_allclose(q.expected_entropy(post), direct, rtol=1e-9)
