"""The session path of psyop power and the direct re-simulation (same schedules and observer draws,
no sessions) on identical seeds: every replication's p values must be identical. This is the check
behind bench_power's agreement claim, at a size the suite can afford."""

from pathlib import Path

import pytest

from psyop.errors import UserError
from psyop.power.direct import direct_trials, run_direct_replication
from psyop.power.replicate import ReplicationTask, run_replication

pytestmark = pytest.mark.cross_cpu

ROOT = Path(__file__).resolve().parents[2]


def _task(name: str, participants: int, replication: int, seed: int = 2020) -> ReplicationTask:
    path = ROOT / "protocols" / f"{name}.yaml"
    return ReplicationTask(path.read_text(), str(path), (), participants, replication, seed)


@pytest.mark.parametrize("name, participants, replications", [("discrimination", 3, 2), ("ordinal", 3, 1)])
def test_session_path_and_direct_path_give_identical_p_values(name: str, participants: int, replications: int) -> None:
    for r in range(replications):
        task = _task(name, participants, r)
        session, direct = run_replication(task), run_direct_replication(task)
        assert session.n_trials == direct.n_trials
        assert len(session.outcomes) >= 2
        assert [(o.test, o.p) for o in session.outcomes] == [(o.test, o.p) for o in direct.outcomes], (name, r)


def test_the_pairing_would_see_a_changed_response() -> None:
    """The comparison can fail: one flipped answer in the direct table changes a fit's p value."""
    from psyop.power.study_tests import study_tests
    from psyop.protocol import load_protocol

    task = _task("discrimination", 3, 0)
    trials = direct_trials(task)
    protocol = load_protocol(ROOT / "protocols" / "discrimination.yaml")
    before = [o.p for o in study_tests(protocol, trials)]
    flipped = trials.copy()
    flipped.loc[flipped.index[:20], "correct"] = ~flipped.loc[flipped.index[:20], "correct"].astype(bool)
    assert [o.p for o in study_tests(protocol, flipped)] != before


def test_direct_path_refuses_reach() -> None:
    with pytest.raises(UserError, match="reach"):
        direct_trials(_task("egocentric", 2, 0))
