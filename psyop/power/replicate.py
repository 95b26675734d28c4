"""One replication: a whole simulated study (compile -> session -> analysis) at one sample size.

A task carries the protocol's text (not a path: a Dask worker may not share this file system),
the observer effects, the sample size, the replication index and the run's seed. Its sessions are
seeded from ``numpy.random.SeedSequence(seed, spawn_key=(participants, replication, j))``, the
key ``SeedSequence.spawn`` would give, so a replication's result depends on nothing but its task:
the same on a local process pool, a Dask cluster, or in this process.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from psyop.power.study_tests import TestOutcome


@dataclass(frozen=True)
class ReplicationTask:
    protocol_text: str
    protocol_name: str
    effects: tuple[tuple[str, object], ...]
    participants: int
    replication: int
    seed: int


@dataclass(frozen=True)
class ReplicationResult:
    participants: int
    replication: int
    outcomes: tuple[TestOutcome, ...]
    n_trials: int


def session_seed(seed: int, participants: int, replication: int, participant_index: int) -> int:
    sequence = np.random.SeedSequence(seed, spawn_key=(participants, replication, participant_index))
    return int(sequence.generate_state(1, dtype=np.uint32)[0])


def run_replication(task: ReplicationTask) -> ReplicationResult:
    from psyop.power.effects import apply_effects
    from psyop.power.study_tests import study_tests
    from psyop.protocol import parse_protocol
    from psyop.schedule import compile_schedule
    from psyop.session.gaze.simulated import SimulatedTrackerConfig
    from psyop.session.runner import SessionOptions, run_session
    from psyop.statistics.dataset import load_dataset

    protocol = apply_effects(parse_protocol(task.protocol_text, task.protocol_name), task.effects)
    study = protocol.study.name
    with tempfile.TemporaryDirectory(prefix="psyop-power-") as tmp:
        data_root = Path(tmp)
        for j in range(task.participants):
            options = SessionOptions(participant=f"S{j + 1:02d}",
                                     seed=session_seed(task.seed, task.participants, task.replication, j),
                                     data_root=data_root, progress=False, write_description=False,
                                     render="cameras", fsync=False,
                                     # power reads trials only: no 120 Hz raw gaze stream (issue 27)
                                     tracker_faults=SimulatedTrackerConfig(raw_stream="requested"))
            run_session(protocol, compile_schedule, options)
        trials = load_dataset(data_root, study).trials
        outcomes = tuple(study_tests(protocol, trials))
    return ReplicationResult(task.participants, task.replication, outcomes, len(trials))
