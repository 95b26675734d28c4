"""One replication: a whole simulated study (compile -> session -> analysis) at one sample size.

A task carries the protocol's text (not a path: a Dask worker may not share this file system),
the observer effects, the sample size, the replication index and the run's seed. Its sessions are
seeded from ``numpy.random.SeedSequence(seed, spawn_key=(participants, replication, j))``, the
key ``SeedSequence.spawn`` would give, so a replication's result depends on nothing but its task:
the same on a local process pool, a Dask cluster, or in this process.
"""

from __future__ import annotations

import functools
import os
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from psyop.power.study_tests import TestOutcome

if TYPE_CHECKING:
    import pandas as pd
    import pyarrow as pa

    from psyop.protocol.model import Protocol
    from psyop.session.log.layout import SessionPaths
    from psyop.run.runner import SessionOptions


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


@functools.lru_cache(maxsize=8)
def _parsed(text: str, name: str, cwd: str) -> Protocol:
    """``parse_protocol(text, name)``, once per process for each protocol text (a worker runs many replications
    of one protocol; parsing its YAML was a tenth of a detection replication). The parsed protocol is frozen
    (pydantic ``frozen=True``) and apply_effects copies it; ``cwd``: relative paths resolve against it."""
    from psyop.protocol import parse_protocol

    return parse_protocol(text, name)


def _sessions(task: ReplicationTask) -> tuple[Protocol, Callable[[Path], list[SessionOptions]]]:
    """The protocol of ``task`` and, per participant, the options of its session (seeded as the
    module docstring says) into ``data_root``."""
    from psyop.power.effects import apply_effects
    from psyop.session.gaze.simulated import SimulatedTrackerConfig
    from psyop.run.runner import SessionOptions

    protocol = apply_effects(_parsed(task.protocol_text, task.protocol_name, os.getcwd()), task.effects)

    def options(data_root: Path) -> list[SessionOptions]:
        from psyop.mesh.load import MeshFiles

        # one model cache for the replication's sessions (each checks every file's SHA-256 before reusing a
        # parse): a mesh protocol's glTF models were parsed again for every session's session.json
        meshes = MeshFiles(Path(task.protocol_name).parent if task.protocol_name else Path.cwd())
        return [SessionOptions(participant=f"S{j + 1:02d}",
                               seed=session_seed(task.seed, task.participants, task.replication, j),
                               data_root=data_root, progress=False, write_description=False,
                               render="cameras", fsync=False,
                               # power reads trials only: no 120 Hz raw gaze stream
                               tracker_faults=SimulatedTrackerConfig(raw_stream="requested"), mesh_files=meshes)
                for j in range(task.participants)]
    return protocol, options


#: where a replication's in-memory sessions say they are (nothing is written there: MemoryLog)
_NOWHERE = Path("psyop-power-in-memory")


def replication_trials(task: ReplicationTask) -> tuple[Protocol, pd.DataFrame]:
    """The protocol of ``task`` and the trial table its analysis sees, as ``psyop power`` makes it:
    each participant's session through the real ``run_session`` loop into an in-memory log
    (psyop.power.memory_log: no files, no fsync, no parquet round trip, no frame tables, raw gaze
    only for the protocol's quality: rules), handed over as load_dataset would have read it back
    (the rules' exclusions left out). Equal, frame for frame, to
    :func:`replication_trials_durable` (tests/power/test_memory_log.py)."""
    from psyop.power.memory_log import MemoryLog, analysis_trials
    from psyop.schedule import compile_schedule
    from psyop.run.runner import run_session

    protocol, options = _sessions(task)
    logs: list[MemoryLog] = []

    def memory_log(paths: SessionPaths, schema: pa.Schema) -> MemoryLog:
        logs.append(MemoryLog(paths, schema, keep_gaze=protocol.quality is not None))  # the rules' measures read it
        return logs[-1]

    for session in options(_NOWHERE):
        run_session(protocol, compile_schedule, session, store_factory=memory_log)
    return protocol, analysis_trials(logs, protocol.quality)


def replication_trials_durable(task: ReplicationTask) -> tuple[Protocol, pd.DataFrame]:
    """The full path through durable logs, kept for comparisons only (tests, benchmarks): every
    session into a durable log in a temporary data directory, finalised to parquet and read back
    by ``load_dataset``."""
    import warnings

    from psyop.schedule import compile_schedule
    from psyop.run.runner import run_session
    from psyop.statistics.dataset import LowGazeWarning, load_dataset

    protocol, options = _sessions(task)
    with tempfile.TemporaryDirectory(prefix="psyop-power-") as tmp:
        data_root = Path(tmp)
        for session in options(data_root):
            run_session(protocol, compile_schedule, session)
        with warnings.catch_warnings():  # the in-memory path counts no low-gaze trials either
            warnings.simplefilter("ignore", LowGazeWarning)
            trials = load_dataset(data_root, protocol.study.name).trials
    return protocol, trials


def run_replication(task: ReplicationTask) -> ReplicationResult:
    """One replication as ``psyop power`` runs it (:func:`replication_trials`, then the study's tests)."""
    from psyop.power.study_tests import study_tests

    protocol, trials = replication_trials(task)
    return ReplicationResult(task.participants, task.replication, tuple(study_tests(protocol, trials)), len(trials))


def run_replication_durable(task: ReplicationTask) -> ReplicationResult:
    """:func:`run_replication` on the full path (:func:`replication_trials_durable`), for comparisons."""
    from psyop.power.study_tests import study_tests

    protocol, trials = replication_trials_durable(task)
    return ReplicationResult(task.participants, task.replication, tuple(study_tests(protocol, trials)), len(trials))
