"""How far each simulated answer is from flipping with the last bits of the CPU (docs/architecture.md,
"Reproducibility across CPUs").

A simulated observer answers a trial by one uniform draw ``u`` against a probability ``p``
(:meth:`psyop.session.responses.simulated.SimulatedObserver.decision`). ``u`` is exact on every IEEE-754
machine (keyed integers times 2**-53); ``p`` goes through libm's erf and numpy's normal draws, whose last bits
may differ between CPUs (a few 1e-16). An answer can differ between two machines only if ``|u - p|`` is below
that difference, so for a uniform ``u`` the rate is at most twice the difference per trial: about 1e-15.

Measured here: no trial of the first :data:`PARTICIPANTS` simulated participants of each shipped study (psyop
simulate's seeds for base seed 2020) lies within :data:`FLIP_MARGIN` of its probability, so none of the answers
the recorded sessions and make figures' simulated data hold can flip on another CPU.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from psyop.protocol import load_protocol
from psyop.run.simulate import plan_jobs
from psyop.schedule import compile_schedule
from psyop.schedule.counterbalance import resolve_participant_index
from psyop.session.plan import compile_plan
from psyop.session.responses.simulated import SimulatedObserver, make_observer

ROOT = Path(__file__).resolve().parents[2]
#: six orders of magnitude above the cross-CPU difference of ``p`` (a few 1e-16)
FLIP_MARGIN = 1e-9
PARTICIPANTS = 20
#: the shipped studies whose observer answers by a draw against a probability (egocentric's reach is continuous)
DRAWING = ("detection", "discrimination", "ordinal", "realism")

pytestmark = pytest.mark.cross_cpu


def margins(observer: SimulatedObserver, rows: list[dict]) -> list[tuple[float, int]]:
    """``(|u - p|, trial)`` of each row the observer answers by a draw."""
    out = []
    for row in rows:
        decision = observer.decision(row)
        if decision is not None:
            u, p = decision
            out.append((abs(u - p), int(row["trial"])))
    return out


def _study_margins(study: str) -> list[tuple[float, int]]:
    path = ROOT / "protocols" / f"{study}.yaml"
    protocol = load_protocol(path)
    params = compile_plan(protocol).observer_params()
    assert params is not None
    found = []
    for job in plan_jobs([path], 2020, {study: PARTICIPANTS}):
        index = resolve_participant_index(None, job.participant, None)
        rows = compile_schedule(protocol, job.seed, participant_index=index).to_dict("records")
        found += margins(make_observer(params, seed=job.seed, participant=job.participant), rows)
    return found


@pytest.mark.parametrize("study", DRAWING)
def test_no_shipped_answer_is_within_reach_of_the_last_bits(study: str) -> None:
    found = _study_margins(study)
    assert len(found) >= 40 * PARTICIPANTS
    smallest = min(found)
    assert smallest[0] > FLIP_MARGIN, f"{study}: trial {smallest[1]} answers by |u - p| = {smallest[0]:.3g}"


def test_the_margin_check_can_fail(monkeypatch: pytest.MonkeyPatch) -> None:
    """An observer whose probability equals its draw has margin 0, which the check reports."""
    path = ROOT / "protocols" / "detection.yaml"
    protocol = load_protocol(path)
    params = compile_plan(protocol).observer_params()
    assert params is not None
    observer = make_observer(params, seed=1, participant="S01")
    row = compile_schedule(protocol, 1, participant_index=1).to_dict("records")[0]
    u, p = observer.decision(row) or (0.0, 0.0)
    monkeypatch.setattr(type(observer.model), "probability", lambda _self, _row, _participant: u)
    assert margins(observer, [row]) == [(0.0, int(row["trial"]))]
    assert 0.0 < abs(u - p)


def test_reach_answers_are_not_draws() -> None:
    protocol = load_protocol(ROOT / "protocols" / "egocentric.yaml")
    params = compile_plan(protocol).observer_params()
    assert params is not None
    assert make_observer(params, seed=1, participant="S01").decision({}) is None
