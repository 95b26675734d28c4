"""Plan the replications of a power run and collect the table."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import pandas as pd

from psyop.errors import UserError
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
    #: the replications run are ``first_replication .. replications - 1`` (precise_power adds batches)
    first_replication: int = 0


def observer_named(path: Path) -> str:
    """Which simulated observer answers the protocol at ``path`` in every replication, as a power run's output
    names it: ``observer: image (from the rendered frames)`` or ``observer: <kind> (from the schedule)``."""
    from psyop.protocol import load_protocol

    observer = load_protocol(path).observer
    if observer is None:
        return "observer: none"
    source = "from the rendered frames" if observer.kind == "image" else "from the schedule"
    return f"observer: {observer.kind} ({source})"


def plan_tasks(run: PowerRun) -> list[ReplicationTask]:
    from psyop.power.effects import apply_effects
    from psyop.protocol import load_protocol

    protocol = load_protocol(run.protocol_path)
    apply_effects(protocol, run.effects)  # fail here, before any worker starts
    text = run.protocol_path.read_text()
    return [ReplicationTask(text, str(run.protocol_path), run.effects, n, r, run.seed)
            for n in run.participants for r in range(run.first_replication, run.replications)]


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


@dataclass(frozen=True)
class Precision:
    """``--precision``: the largest half-width of a power's 95 % Clopper-Pearson interval, and the
    most replications per n spent reaching it (``--max-replications``)."""

    half_width: float
    max_replications: int

    def __post_init__(self) -> None:
        if not 0 < self.half_width < 0.5:
            raise UserError(f"--precision must be in (0, 0.5) (a CI half-width on power), got {self.half_width:g}",
                            "--precision")
        if self.max_replications < 1:
            raise UserError(f"--max-replications must be >= 1, got {self.max_replications}", "--max-replications")


def half_width(table: pd.DataFrame) -> float:
    """The widest half-width of the power intervals in ``table`` (0 for an empty table)."""
    return float(((table["ci_high"] - table["ci_low"]) / 2.0).max()) if len(table) else 0.0


def precise_power(run: PowerRun, precision: Precision, resumed: list[int] | None = None,
                  short: list[str] | None = None,
                  replicate: Callable[[ReplicationTask], ReplicationResult] = run_replication,
                  ) -> tuple[pd.DataFrame, list[ReplicationResult]]:
    """:func:`run_power` with as many replications per n as ``precision`` needs: at each n first
    ``run.replications``, then doubled (2R, 4R, ..., capped at ``precision.max_replications``) until
    every test's 95 % interval at that n is at most ``precision.half_width`` either side. Replication
    r has the same seed as in any run (only more of them are run), so a batch resumes from the
    checkpoint like a rerun. An n whose interval is still wider at the cap is described in ``short``."""
    results: list[ReplicationResult] = []
    for n in run.participants:
        at_n: list[ReplicationResult] = []
        done, want = 0, min(run.replications, precision.max_replications)
        while True:
            _, fresh = run_power(replace(run, participants=(n,), replications=want, first_replication=done), resumed,
                                 replicate)
            at_n += fresh
            done, widest = want, half_width(power_table(at_n, run.alpha))
            if widest <= precision.half_width or done >= precision.max_replications:
                break
            want = min(2 * done, precision.max_replications)
        if widest > precision.half_width and short is not None:
            short.append(f"n = {n}: a 95 % CI half-width is {widest:.3f} after --max-replications "
                         f"{precision.max_replications}, wider than --precision {precision.half_width:g}")
        results += at_n
    return power_table(results, run.alpha), results
