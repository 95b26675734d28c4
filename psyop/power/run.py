"""Plan the replications of a power run and collect the table."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from psyop.power.executors import run_dask, run_local
from psyop.power.replicate import ReplicationResult, ReplicationTask, run_replication
from psyop.power.summary import power_table


@dataclass(frozen=True)
class PowerRun:
    protocol_path: Path
    participants: tuple[int, ...]
    replications: int
    seed: int = 0
    effects: tuple[tuple[str, object], ...] = ()
    alpha: float = 0.05
    scheduler: str | None = None
    jobs: int = 1
    progress: bool = False


def plan_tasks(run: PowerRun) -> list[ReplicationTask]:
    from psyop.power.effects import apply_effects
    from psyop.protocol import load_protocol

    protocol = load_protocol(run.protocol_path)
    apply_effects(protocol, run.effects)  # fail here, before any worker starts
    text = run.protocol_path.read_text()
    return [ReplicationTask(text, str(run.protocol_path), run.effects, n, r, run.seed)
            for n in run.participants for r in range(run.replications)]


def run_power(run: PowerRun) -> tuple[pd.DataFrame, list[ReplicationResult]]:
    tasks = plan_tasks(run)
    if run.scheduler:
        results = run_dask(run_replication, tasks, run.scheduler, run.progress)
    else:
        results = run_local(run_replication, tasks, run.jobs, run.progress)
    return power_table(results, run.alpha), results
