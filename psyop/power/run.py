"""Plan the replications of a power run and collect the table."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from psyop.power.checkpoint import Checkpoint
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
    #: where finished replications are kept (psyop.power.checkpoint); None: nowhere
    checkpoint: Path | None = None
    #: a cluster without any worker for this long is lost (exit 3)
    lost_after_s: float = 60.0


def plan_tasks(run: PowerRun) -> list[ReplicationTask]:
    from psyop.power.effects import apply_effects
    from psyop.protocol import load_protocol

    protocol = load_protocol(run.protocol_path)
    apply_effects(protocol, run.effects)  # fail here, before any worker starts
    text = run.protocol_path.read_text()
    return [ReplicationTask(text, str(run.protocol_path), run.effects, n, r, run.seed)
            for n in run.participants for r in range(run.replications)]


def run_power(run: PowerRun, resumed: list[int] | None = None,
              replicate: Callable[[ReplicationTask], ReplicationResult] = run_replication,
              ) -> tuple[pd.DataFrame, list[ReplicationResult]]:
    """The power table and every replication's result, in task order; ``replicate`` runs one
    replication (tests and benchmarks pass psyop.power.replicate.run_replication_durable, the full
    path, to compare).

    With ``run.checkpoint``, each finished replication is kept there as it arrives and the kept
    ones are not run again (their count is appended to ``resumed``); an interrupted or failed
    run loses only the replications that were running."""
    tasks = plan_tasks(run)
    store = Checkpoint(run.checkpoint) if run.checkpoint is not None else None
    kept = [store.load(task) if store is not None else None for task in tasks]
    todo = [i for i, result in enumerate(kept) if result is None]
    if resumed is not None:
        resumed.append(len(tasks) - len(todo))

    def keep(j: int, result: ReplicationResult) -> None:
        if store is not None:
            store.save(tasks[todo[j]], result)

    remaining = [tasks[i] for i in todo]
    if not remaining:
        fresh: list[ReplicationResult] = []
    elif run.scheduler:
        fresh = run_dask(replicate, remaining, run.scheduler, run.progress, on_result=keep,
                         lost_after_s=run.lost_after_s,
                         describe=lambda t: f"replication {t.replication} at {t.participants} participants")
    else:
        fresh = run_local(replicate, remaining, run.jobs, run.progress, on_result=keep)
    for i, result in zip(todo, fresh):
        kept[i] = result
    results = [r for r in kept if r is not None]
    return power_table(results, run.alpha), results
