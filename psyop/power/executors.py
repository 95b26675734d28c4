"""Where replications run: local processes (default) or a Dask cluster (``--scheduler``).

Both return results in task order, so the power table does not depend on the executor, and
both hand each result to ``on_result`` as soon as it arrives (psyop.power.checkpoint keeps it
durably). psyop schedules nothing itself: the local path is
``concurrent.futures.ProcessPoolExecutor`` (spawned workers, as ``psyop simulate``), the
cluster path ``distributed.Client.submit`` / ``distributed.wait``.

Faults end promptly: Ctrl-C stops the local workers at once (they are terminated, not waited
for: a replication takes many seconds); a cluster that has lost every worker for
``lost_after_s``, or its scheduler, is a :class:`~psyop.errors.UserError` with exit code 3
(:data:`CLUSTER_LOST_EXIT`), never a hang or a traceback.
"""

from __future__ import annotations

import multiprocessing
import time
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import TypeVar

from psyop.errors import UserError

T = TypeVar("T")
R = TypeVar("R")

_SPAWN = multiprocessing.get_context("spawn")
#: exit code of a power run whose cluster was lost (a device-like failure, as a lost tracker in `psyop run`)
CLUSTER_LOST_EXIT = 3


def _bar(total: int, progress: bool, description: str):
    from tqdm import tqdm

    return tqdm(total=total, desc=description, unit="replication", disable=not progress, leave=False)


def _ignore(index: int, result: object) -> None:
    return None


def run_local(function: Callable[[T], R], tasks: Sequence[T], jobs: int, progress: bool = False,
              on_result: Callable[[int, R], None] = _ignore) -> list[R]:
    results: list[R | None] = [None] * len(tasks)
    with _bar(len(tasks), progress, "psyop power (local)") as bar:
        if jobs <= 1:
            for i, task in enumerate(tasks):
                results[i] = function(task)
                on_result(i, results[i])  # type: ignore[arg-type]
                bar.update(1)
            return results  # type: ignore[return-value]
        pool = ProcessPoolExecutor(max_workers=jobs, mp_context=_SPAWN)
        try:
            futures = {pool.submit(function, task): i for i, task in enumerate(tasks)}
            pending = set(futures)
            while pending:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                for future in done:
                    results[futures[future]] = future.result()
                    on_result(futures[future], results[futures[future]])  # type: ignore[arg-type]
                    bar.update(1)
        except BaseException:
            _stop_now(pool)
            raise
        pool.shutdown(wait=True)
    return results  # type: ignore[return-value]


def _stop_now(pool: ProcessPoolExecutor) -> None:
    """Cancel what is queued and terminate the workers (shutdown alone waits for running tasks)."""
    processes = list(getattr(pool, "_processes", {}).values())  # no public handle on the workers
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        if process.is_alive():
            process.terminate()
    for process in processes:
        process.join(timeout=10)


def run_dask(function: Callable[[T], R], tasks: Sequence[T], scheduler: str, progress: bool = False,
             timeout_s: float = 30.0, on_result: Callable[[int, R], None] = _ignore,
             lost_after_s: float = 60.0, poll_s: float = 1.0,
             describe: Callable[[T], str] = lambda task: "a task") -> list[R]:
    """Run ``tasks`` on the Dask scheduler at ``scheduler``.

    No worker for ``lost_after_s`` (all killed, none started), a scheduler that is gone, or
    tasks the cluster cancelled end in a UserError with exit code 3 naming the scheduler; a task
    whose workers kept dying (distributed's ``KilledWorker``) in one with exit code 3 naming it
    (``describe``); every result that arrived before was handed to ``on_result``."""
    import logging

    client = _connect(scheduler, timeout_s)
    # a lost scheduler makes the client log reconnect tracebacks: the UserError says it in one line
    # and a result fetch given up on (_result) leaves a task whose AllExit asyncio logs when collected
    quiet = [logging.getLogger("distributed.client"), logging.getLogger("asyncio")]
    levels = [logger.level for logger in quiet]
    for logger in quiet:
        logger.setLevel(logging.CRITICAL)
    futures: list = []
    try:
        futures = [client.submit(function, task, pure=False) for task in tasks]
        with _bar(len(tasks), progress, f"psyop power ({scheduler})") as bar:
            return _gather(client, futures, tasks, scheduler, bar, on_result, describe,
                           timeout_s=timeout_s, lost_after_s=lost_after_s, poll_s=poll_s)
    except KeyboardInterrupt:
        if client.status == "running":
            client.cancel([f for f in futures if not f.done()], force=True)
        raise
    finally:
        try:
            client.close(timeout=5)
        except Exception:  # noqa: BLE001 - a dead scheduler: nothing left to close
            pass
        finally:
            import gc

            gc.collect()  # collect those tasks while asyncio is quiet
            for logger, level in zip(quiet, levels):
                logger.setLevel(level)


def _connect(scheduler: str, timeout_s: float):
    """A ``distributed.Client`` on ``scheduler``, or a UserError (exit 2) saying how to start one."""
    try:
        from distributed import Client
    except ImportError:
        raise UserError("--scheduler needs dask.distributed: pip install 'dask[distributed]'", "--scheduler") from None
    try:
        return Client(scheduler, timeout=timeout_s)
    except (OSError, TimeoutError) as exc:
        raise UserError(f"cannot reach the Dask scheduler at {scheduler}: {exc}. Start one with "
                        "`dask scheduler` and workers with `dask worker tcp://HOST:8786` (docs/adaptive.md)",
                        "--scheduler") from None


def _lost(scheduler: str, why: str) -> UserError:
    return UserError(f"lost the Dask cluster at {scheduler}: {why}; the finished replications are kept, "
                     "restart the cluster and rerun the same command to resume", "--scheduler",
                     exit_code=CLUSTER_LOST_EXIT)


def _gather(client, futures: list, tasks: Sequence[T], scheduler: str, bar, on_result: Callable[[int, R], None],
            describe: Callable[[T], str], timeout_s: float, lost_after_s: float, poll_s: float) -> list[R]:
    """Wait for ``futures`` (in ``tasks`` order), handing each result to ``on_result`` as it arrives,
    and check the cluster between waits that returned nothing."""
    index = {f.key: i for i, f in enumerate(futures)}
    results: list[R | None] = [None] * len(tasks)
    pending = set(futures)
    no_workers_since: list[float | None] = [None]

    def check() -> None:
        no_workers_since[0] = _check_cluster(client, scheduler, timeout_s, lost_after_s, no_workers_since[0])

    while pending:
        done, pending = _wait_some(pending, poll_s, scheduler)
        for future in done:
            i = index[future.key]
            results[i] = _result(future, scheduler, lambda: describe(tasks[i]), poll_s, check)
            on_result(i, results[i])  # type: ignore[arg-type]
            bar.update(1)
        if not done:
            check()
    return results  # type: ignore[return-value]


def _wait_some(pending: set, poll_s: float, scheduler: str) -> tuple[set, set]:
    """The futures of ``pending`` done within ``poll_s`` and those still pending."""
    from distributed import wait as dask_wait

    try:
        done, still = dask_wait(list(pending), timeout=poll_s, return_when="FIRST_COMPLETED")
        return set(done), set(still)
    except TimeoutError:
        return set(), pending
    except Exception as exc:
        if "Cancelled" in type(exc).__name__ or _connection_lost(exc):
            raise _lost(scheduler, f"the scheduler connection was lost ({type(exc).__name__})") from None
        raise


def _result(future, scheduler: str, describe: Callable[[], str], poll_s: float, check: Callable[[], None]):
    """A done future's result; a cancelled task or a lost connection is a lost cluster (exit 3), a task
    whose workers kept dying one line naming it (exit 3), and a replication's own error is raised.

    The result is fetched in waits of ``poll_s`` with ``check`` (the cluster's health) between them:
    a result held by a worker that dies before the client fetched it is computed again, and with every
    worker gone ``future.result()`` would wait for ever (seen under load: no exit within 180 s). A future whose
    status is ``lost`` (its result was on a worker that died: the scheduler computes it again, as the
    client still holds it) is waited for like any other, not a lost cluster (seen once under load: the
    worker that a later task killed held the earlier tasks' results)."""
    if future.status == "cancelled" or future.cancelled():
        raise _lost(scheduler, "the scheduler cancelled its tasks (it was stopped or restarted)")
    try:
        while True:
            try:
                return future.result(timeout=poll_s)
            except TimeoutError:
                check()
    except Exception as exc:
        if type(exc).__name__ in ("CancelledError", "FutureCancelledError"):
            raise _lost(scheduler, f"the scheduler cancelled its tasks ({type(exc).__name__})") from None
        if future.status != "error" and _connection_lost(exc):  # not the replication's own error
            raise _lost(scheduler, f"the scheduler connection was lost ({type(exc).__name__})") from None
        if type(exc).__name__ == "KilledWorker":  # its workers died again and again
            why = " ".join(str(exc).split())  # distributed's message has line breaks: one line
            raise UserError(f"{describe()} killed every worker that ran it ({why}); the finished replications "
                            "are kept, rerun the same command to resume", "--scheduler",
                            exit_code=CLUSTER_LOST_EXIT) from None
        raise


def _check_cluster(client, scheduler: str, timeout_s: float, lost_after_s: float,
                   no_workers_since: float | None) -> float | None:
    """Raise a lost cluster (exit 3) when the client is closed, the scheduler does not answer or no
    worker was there for ``lost_after_s``; return since when there has been no worker (None: there is one)."""
    if client.status not in ("running", "connecting", "newly-created"):
        raise _lost(scheduler, f"the client is {client.status}")
    n_workers = _n_workers(client, timeout_s)
    if n_workers is None:
        raise _lost(scheduler, "the scheduler does not answer")
    now = time.monotonic()
    if n_workers:
        return None
    if no_workers_since is None:
        return now
    if now - no_workers_since > lost_after_s:
        raise _lost(scheduler, f"no worker for {lost_after_s:g} s")
    return no_workers_since


def _connection_lost(exc: BaseException) -> bool:
    """Whether ``exc`` is the client's connection to the scheduler failing (a reset or closed
    socket: an OSError, or distributed's CommClosedError), not a replication's own error. Under load
    a killed scheduler surfaces as ``ConnectionResetError`` from the wait, which the CLI would
    otherwise report as a file I/O error (exit 2) instead of a lost cluster (exit 3)."""
    from distributed.comm.core import CommClosedError

    return isinstance(exc, (OSError, CommClosedError))


def _n_workers(client: object, timeout_s: float) -> int | None:
    """Workers the scheduler has now; None when the scheduler does not answer within ``timeout_s``."""
    try:
        return len(client.nthreads())  # type: ignore[attr-defined]
    except Exception:  # noqa: BLE001 - OSError, CommClosedError, TimeoutError: the scheduler is gone
        return None
