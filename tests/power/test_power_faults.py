"""Power that survives: Ctrl-C stops a local run within seconds and keeps every finished
replication; a rerun with the same arguments resumes them and gives the uninterrupted table; a
real Dask cluster on 127.0.0.1 that loses all its workers or its scheduler ends in one line and
exit 3 within a bounded time.

Real processes and real signals: `psyop power` runs as a child process, the cluster's workers
(and, for the scheduler test, the scheduler) are `dask` processes killed with SIGKILL.
"""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from psyop.power.run import PowerRun, run_power

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "session"))
from session_helpers import wait_until

ROOT = Path(__file__).resolve().parents[2]
DASK = Path(sys.executable).with_name("dask")


@pytest.fixture(scope="module")
def small_realism(tmp_path_factory) -> Path:
    text = (ROOT / "protocols" / "realism.yaml").read_text()
    path = tmp_path_factory.mktemp("protocols") / "realism_small.yaml"
    path.write_text(text.replace("repetitions: 15 ", "repetitions: 3 "))
    return path


def _power(protocol: Path, checkpoint: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "psyop", "power", str(protocol), "--participants", "2,3", "--replications", "6",
            "--seed", "5", "--jobs", "2", "--no-progress", "--checkpoint", str(checkpoint), *extra]


def test_ctrl_c_stops_within_seconds_and_a_rerun_resumes_to_the_same_table(small_realism: Path,
                                                                           tmp_path: Path) -> None:
    reference, _ = run_power(PowerRun(protocol_path=small_realism, participants=(2, 3), replications=6, seed=5))
    checkpoint = tmp_path / "kept"
    process = subprocess.Popen(_power(small_realism, checkpoint), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    wait_until(lambda: len(list(checkpoint.glob("*.json"))) >= 2 or process.poll() is not None, timeout_s=300,
               what="two finished replications")
    assert process.poll() is None, "the run finished before the interrupt: give it more replications"
    process.send_signal(signal.SIGINT)
    sent = time.monotonic()
    _, stderr = process.communicate(timeout=60)
    stopped_s = time.monotonic() - sent
    kept = len(list(checkpoint.glob("*.json")))
    assert process.returncode == 130, stderr
    assert "Traceback" not in stderr and "rerun the same command to resume" in stderr, stderr
    assert 2 <= kept < 12
    # stopped, not finished: at most the two running replications ended after the signal
    assert kept <= 12 - 2, f"{kept} kept after {stopped_s:.1f} s"
    done = subprocess.run(_power(small_realism, checkpoint), capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert f"{kept} of them resumed" in done.stdout
    from psyop.power.summary import format_table

    assert format_table(reference) in done.stdout  # the resumed table is the uninterrupted one
    resumed, _ = run_power(PowerRun(protocol_path=small_realism, participants=(2, 3), replications=6, seed=5,
                                    checkpoint=checkpoint))
    pd.testing.assert_frame_equal(resumed, reference)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start(argv: list[str]) -> subprocess.Popen[bytes]:
    return subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


@pytest.mark.parametrize("kill", ["every worker", "the scheduler"])
def test_a_lost_cluster_ends_in_one_line_and_exit_3(small_realism: Path, tmp_path: Path, kill: str) -> None:
    pytest.importorskip("distributed")
    from distributed import Client

    address = f"tcp://127.0.0.1:{_free_port()}"
    scheduler = _start([str(DASK), "scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":", 1)[1],
                        "--no-dashboard"])
    workers: list[subprocess.Popen[bytes]] = []
    try:
        for _ in range(2):
            workers.append(_start([str(DASK), "worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard",
                                   "--host", "127.0.0.1"]))

        def two_workers() -> bool:
            try:
                with Client(address, timeout=5) as client:
                    return len(client.nthreads()) == 2
            except OSError:
                return False
        wait_until(two_workers, timeout_s=120, poll_s=0.5, what="a cluster of two workers")
        checkpoint = tmp_path / "kept"
        process = subprocess.Popen(_power(small_realism, checkpoint, "--scheduler", address, "--replications", "30",
                                          "--lost-after-s", "10"),
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        wait_until(lambda: any(checkpoint.glob("*.json")) or process.poll() is not None, timeout_s=300,
                   what="a finished replication")
        assert process.poll() is None
        for victim in (workers if kill == "every worker" else [scheduler]):
            victim.send_signal(signal.SIGKILL)
            victim.wait(timeout=30)
        _, stderr = process.communicate(timeout=180)  # bounded: 10 s without workers, or the lost connection
        assert process.returncode == 3, stderr
        lines = [line for line in stderr.splitlines() if line.strip()]
        assert len(lines) == 1 and "lost the Dask cluster" in lines[0] and "rerun the same command" in lines[0], stderr
        assert any(checkpoint.glob("*.json"))  # what finished before the loss is kept
    finally:
        for p in (*workers, scheduler):
            if p.poll() is None:
                p.kill()
                p.wait(timeout=30)


def _wait_for_restarted_worker(cluster, deadline_s: float = 120.0) -> None:
    """Let the nanny finish restarting the worker the task killed before the cluster closes: closing
    while the new worker process is not yet started fails inside distributed's Nanny.kill ("can only
    join a started process", seen once in a loaded CI run), after psyop's behaviour was already checked."""
    import time

    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        procs = [getattr(w, "process", None) for w in cluster.workers.values()]
        if procs and all(p is not None and p.pid is not None for p in procs) and cluster.scheduler_info.get("workers"):
            return
        time.sleep(0.1)


def test_a_replication_whose_workers_keep_dying_ends_in_one_line_naming_it_and_exit_3() -> None:
    """A real LocalCluster with nannies: the last task kills the worker process that runs it, the
    nanny restarts the worker, the task kills it again until distributed gives up (KilledWorker).
    run_dask must turn that into one UserError (exit 3) naming the task, after handing every
    task that finished to ``on_result`` (the CLI's checkpoint)."""
    pytest.importorskip("distributed")
    import dask
    from distributed import LocalCluster

    from psyop.errors import UserError
    from psyop.power.executors import CLUSTER_LOST_EXIT, run_dask

    def square_or_die(task: int) -> int:
        import os

        if task == 3:
            os._exit(1)  # the worker process dies, as an out-of-memory kill would
        return task * task

    kept: dict[int, int] = {}
    # one task on the worker at a time: distributed also blames the tasks queued on a dying worker
    with dask.config.set({"distributed.scheduler.allowed-failures": 1, "distributed.scheduler.worker-saturation": 1.0}):
        with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None,
                          host="127.0.0.1") as cluster:
            with pytest.raises(UserError) as caught:
                run_dask(square_or_die, [0, 1, 2, 3], cluster.scheduler_address, on_result=kept.__setitem__,
                         lost_after_s=120, describe=lambda task: f"replication {task}")
            _wait_for_restarted_worker(cluster)
    error = caught.value
    assert error.exit_code == CLUSTER_LOST_EXIT
    message = error.message
    assert "\n" not in message and message.startswith("replication 3 killed every worker"), message
    assert "rerun the same command" in message
    assert kept == {0: 0, 1: 1, 2: 4}  # the finished ones were handed on before the error
