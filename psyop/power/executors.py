"""Where replications run: local processes (default) or a Dask cluster (``--scheduler``).

Both return results in task order, so the power table does not depend on the executor. psyop
schedules nothing itself: the local path is ``concurrent.futures.ProcessPoolExecutor`` (spawned
workers, as ``psyop simulate``), the cluster path ``distributed.Client.submit`` /
``distributed.as_completed``.
"""

from __future__ import annotations

import multiprocessing
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Callable, Sequence, TypeVar

from psyop.errors import UserError

T = TypeVar("T")
R = TypeVar("R")

_SPAWN = multiprocessing.get_context("spawn")


def _bar(total: int, progress: bool, description: str):
    from tqdm import tqdm

    return tqdm(total=total, desc=description, unit="replication", disable=not progress, leave=False)


def run_local(function: Callable[[T], R], tasks: Sequence[T], jobs: int, progress: bool = False) -> list[R]:
    results: list[R | None] = [None] * len(tasks)
    with _bar(len(tasks), progress, "psyop power (local)") as bar:
        if jobs <= 1:
            for i, task in enumerate(tasks):
                results[i] = function(task)
                bar.update(1)
        else:
            with ProcessPoolExecutor(max_workers=jobs, mp_context=_SPAWN) as pool:
                futures = {pool.submit(function, task): i for i, task in enumerate(tasks)}
                for future in as_completed(futures):
                    results[futures[future]] = future.result()
                    bar.update(1)
    return results  # type: ignore[return-value]


def run_dask(function: Callable[[T], R], tasks: Sequence[T], scheduler: str, progress: bool = False,
             timeout_s: float = 30.0) -> list[R]:
    try:
        from distributed import Client, as_completed as dask_as_completed
    except ImportError:
        raise UserError("--scheduler needs dask.distributed: pip install 'dask[distributed]'", "--scheduler") from None
    try:
        client = Client(scheduler, timeout=timeout_s)
    except (OSError, TimeoutError) as exc:
        raise UserError(f"cannot reach the Dask scheduler at {scheduler}: {exc}. Start one with "
                        "`dask scheduler` and workers with `dask worker tcp://HOST:8786` (docs/adaptive.md)",
                        "--scheduler") from None
    try:
        futures = [client.submit(function, task, pure=False) for task in tasks]
        index = {f.key: i for i, f in enumerate(futures)}
        results: list[R | None] = [None] * len(tasks)
        with _bar(len(tasks), progress, f"psyop power ({scheduler})") as bar:
            for future in dask_as_completed(futures):
                results[index[future.key]] = future.result()
                bar.update(1)
        return results  # type: ignore[return-value]
    finally:
        client.close()
