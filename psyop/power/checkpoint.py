"""Finished replications of a power run, kept durably so that a rerun resumes them.

One JSON file per replication, written atomically (psyop.atomic) as soon as its result reaches
the parent process, named by the SHA-256 of everything the result depends on: the protocol
text, the effects, the run's seed, the sample size and the replication index (a replication is
a pure function of its task, psyop.power.replicate). A rerun with the same arguments finds them
and runs only the rest, so the resumed table equals an uninterrupted run's. A file that cannot
be read, or that holds another task, is ignored and its replication run again.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path

from psyop import __version__
from psyop.atomic import write_atomic
from psyop.power.replicate import ReplicationResult, ReplicationTask
from psyop.power.study_tests import TestOutcome

#: where ``psyop power`` keeps finished replications unless ``--checkpoint`` says otherwise
DEFAULT_DIR = Path(".psyop-power")
_MAX_BYTES = 1 << 20


def task_key(task: ReplicationTask) -> str:
    """SHA-256 of what a replication's result depends on (and the psyop version that computed it)."""
    identity = json.dumps({"protocol": task.protocol_text, "effects": [list(e) for e in task.effects],
                           "participants": task.participants, "replication": task.replication,
                           "seed": task.seed, "psyop": __version__}, sort_keys=True, default=str)
    return hashlib.sha256(identity.encode()).hexdigest()


def _float(value: float) -> float | str:
    return value if math.isfinite(value) else repr(value)  # nan/inf as text: strict JSON


@dataclass(frozen=True)
class Checkpoint:
    """The folder of finished replications."""

    directory: Path

    def path(self, task: ReplicationTask) -> Path:
        return self.directory / f"n{task.participants}-r{task.replication}-{task_key(task)[:16]}.json"

    def save(self, task: ReplicationTask, result: ReplicationResult) -> None:
        """Keep ``result`` of ``task`` (atomically: a file is whole or absent)."""
        payload = {"key": task_key(task), "participants": result.participants, "replication": result.replication,
                   "n_trials": result.n_trials,
                   "outcomes": [{"test": o.test, "p": _float(o.p), "note": o.note, "flag": o.flag}
                                for o in result.outcomes]}
        write_atomic(self.path(task), json.dumps(payload, indent=1) + "\n")

    def load(self, task: ReplicationTask) -> ReplicationResult | None:
        """The kept result of ``task``; None when absent, unreadable or another task's."""
        path = self.path(task)
        try:
            if not path.is_file() or path.stat().st_size > _MAX_BYTES:
                return None
            payload = json.loads(path.read_text())
            if payload.get("key") != task_key(task):
                return None
            outcomes = tuple(TestOutcome(str(o["test"]), float(o["p"]), str(o.get("note", "")), str(o.get("flag", "")))
                             for o in payload["outcomes"])
            return ReplicationResult(int(payload["participants"]), int(payload["replication"]), outcomes,
                                     int(payload["n_trials"]))
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            return None
