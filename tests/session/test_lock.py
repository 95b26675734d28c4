"""One writer per session: concurrent `psyop run`/`recover` are refused at once (exit 2,
naming the holder), and a killed holder frees the lock by itself.

Before the lock, two runs on one session both exited 0 'complete' (with different seeds
session.json named one seed and trials.parquet held neither schedule), and three at once
ended in a FileExistsError traceback.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import platform
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from psyop.errors import UserError
from psyop.session.lock import SessionLock
from psyop.session.log.layout import SessionPaths
from psyop.session.log.schema import TIMING_COLUMNS
from session_helpers import small_protocol

SEED = 7
DEADLINE_S = 120.0


def _argv(protocol: Path, data: Path, seed: int, delay_s: float) -> list[str]:
    return [sys.executable, "-m", "psyop", "run", str(protocol), "--participant", "L1", "--seed", str(seed),
            "--data", str(data), "--clock", "virtual", "--no-progress", "--render", "cameras",
            "--phase-delay-s", str(delay_s)]


def _poll(condition, what: str) -> None:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + DEADLINE_S
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.02)


def _holder_pid(paths: SessionPaths) -> int | None:
    try:
        return int(json.loads(paths.lock_file.read_text())["pid"])
    except (OSError, ValueError, KeyError):
        return None


def _comparable(trials: pd.DataFrame) -> pd.DataFrame:
    return trials.drop(columns=[c for c in TIMING_COLUMNS if c in trials]).reset_index(drop=True)


@pytest.fixture(scope="module")
def protocol(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return small_protocol(tmp_path_factory.mktemp("lock"), "detection", 2)


@pytest.fixture(scope="module")
def reference(protocol: Path, tmp_path_factory: pytest.TempPathFactory) -> pd.DataFrame:
    data = tmp_path_factory.mktemp("lock_ref")
    subprocess.run(_argv(protocol, data, SEED, 0.0), check=True, capture_output=True)
    return pd.read_parquet(SessionPaths(data, "detection", "L1", 1).trials_parquet)


@pytest.mark.slow
def test_second_writer_and_recover_are_refused_then_a_killed_holder_frees_the_lock(
        protocol: Path, reference: pd.DataFrame, tmp_path: Path) -> None:
    paths = SessionPaths(tmp_path, "detection", "L1", 1)
    holder = subprocess.Popen(_argv(protocol, tmp_path, SEED, 0.2), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        _poll(lambda: _holder_pid(paths) == holder.pid, "the first run to take the lock")
        for seed in (SEED, 8):  # same seed (would record trials twice) and another seed (would mix schedules)
            second = subprocess.run(_argv(protocol, tmp_path, seed, 0.0), capture_output=True, text=True)
            assert second.returncode == 2, second.stderr
            assert f"pid {holder.pid}" in second.stderr and platform.node() in second.stderr
            assert "Traceback" not in second.stderr
        recover = subprocess.run([sys.executable, "-m", "psyop", "recover", str(tmp_path)], capture_output=True, text=True)
        # the running session is another process's to finish: named, left to it, not a failure (issue 22)
        assert recover.returncode == 0 and f"in use by pid {holder.pid}" in recover.stdout, recover.stderr
        assert "left to it" in recover.stdout
        assert holder.poll() is None, "the first run kept running"
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    assert json.loads(paths.metadata.read_text())["seed"] == SEED
    resumed = subprocess.run(_argv(protocol, tmp_path, SEED, 0.0), capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr  # the kernel released the killed holder's lock
    final = pd.read_parquet(paths.trials_parquet)
    pd.testing.assert_frame_equal(_comparable(final).drop(columns="drift_correction_deg"),
                                  _comparable(reference).drop(columns="drift_correction_deg"), check_dtype=False)


@pytest.mark.slow
def test_three_runs_at_once_one_wins_the_others_exit_2(protocol: Path, reference: pd.DataFrame, tmp_path: Path) -> None:
    runs = [subprocess.Popen(_argv(protocol, tmp_path, SEED, 0.01), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                             text=True) for _ in range(3)]
    results = [(run.wait(timeout=DEADLINE_S), run.stderr.read()) for run in runs]  # type: ignore[union-attr]
    codes = sorted(code for code, _ in results)
    assert codes == [0, 2, 2], results
    for code, err in results:
        assert "Traceback" not in err
        if code == 2:
            # the holder is named when it has written its pid; in the instant between its flock and
            # that write (or its truncate and release) the refusal says so instead (lock._read_holder)
            assert "in use by" in err or "already complete" in err
    final = pd.read_parquet(SessionPaths(tmp_path, "detection", "L1", 1).trials_parquet)
    assert final["trial"].tolist() == reference["trial"].tolist()
    pd.testing.assert_frame_equal(_comparable(final), _comparable(reference), check_dtype=False)


def _hold(path: str, ready_fd: int) -> None:
    SessionLock(Path(path)).acquire()
    os.write(ready_fd, b"x")
    while True:  # held until killed
        signal.pause()


def test_a_killed_holder_frees_the_lock(tmp_path: Path) -> None:
    path = tmp_path / "ses-1" / ".lock"
    read_fd, write_fd = os.pipe()
    child = mp.get_context("fork").Process(target=_hold, args=(str(path), write_fd))
    child.start()
    assert os.read(read_fd, 1) == b"x"
    with pytest.raises(UserError, match=f"pid {child.pid} on host"):
        SessionLock(path).acquire()
    os.kill(child.pid, signal.SIGKILL)
    child.join()
    lock = SessionLock(path)
    lock.acquire()  # at once: no stale-lock cleanup needed
    assert lock.held
    lock.release()
    os.close(read_fd)
    os.close(write_fd)


def test_the_lock_is_exclusive_within_one_process_too(tmp_path: Path) -> None:
    first = SessionLock(tmp_path / ".lock")
    first.acquire()
    with pytest.raises(UserError, match=f"pid {os.getpid()}"):
        SessionLock(tmp_path / ".lock").acquire()
    first.release()
    SessionLock(tmp_path / ".lock").acquire()


def test_a_refused_writer_waits_for_the_holders_description_then_names_it(tmp_path: Path) -> None:
    import threading

    from psyop.session.lock import _read_holder
    lock_file = tmp_path / ".lock"
    lock_file.write_bytes(b"")
    fd = os.open(lock_file, os.O_RDONLY)
    try:
        assert "had not written its pid" in _read_holder(fd, wait_s=0.0)
        writer = threading.Timer(0.05, lambda: lock_file.write_text(
            json.dumps({"pid": 4242, "host": "lab-pc", "purpose": "run"})))
        writer.start()
        try:
            assert _read_holder(fd, wait_s=30.0).startswith("pid 4242 on host 'lab-pc'")
        finally:
            writer.join()
    finally:
        os.close(fd)
