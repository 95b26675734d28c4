"""SIGKILL an adaptive session at random moments: after each resume the procedure is rebuilt from
the logged trials, so the levels and responses equal an uninterrupted session's.

Kills as in tests/session/test_crash_safety.py: a forked `psyop run` with a small real delay per
phase, killed after a random time; the child announces each trial only after its durable append.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import random
import signal
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from psyop.cli import main as cli_main
from psyop.session.log.layout import SessionPaths

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_adaptive_session import adaptive_detection  # noqa: E402

SEED = 9
COMPARED = ["trial", "condition", "level_D", "correct", "response", "adaptive_procedure", "adaptive_trials",
            "adaptive_estimate_D", "adaptive_estimate_sd_D", "adaptive_step_D", "adaptive_reversals"]


def _child(argv: list[str], announce_fd: int) -> None:
    from psyop.session.log import store

    original = store.SessionStore.append_trial

    def append_and_announce(self, row, frames):  # type: ignore[no-untyped-def]
        original(self, row, frames)
        os.write(announce_fd, f"{int(row['trial'])}\n".encode())

    store.SessionStore.append_trial = append_and_announce  # instrumentation only, after the real append
    os._exit(cli_main(argv))


def _args(protocol: Path, data: Path, delay_s: float) -> list[str]:
    return ["run", str(protocol), "--participant", "K1", "--seed", str(SEED), "--data", str(data),
            "--clock", "virtual", "--no-progress", "--phase-delay-s", str(delay_s), "--render", "cameras"]


def _kill_once(argv: list[str], after_s: float) -> set[int]:
    read_fd, write_fd = os.pipe()
    process = mp.get_context("fork").Process(target=_child, args=(argv, write_fd))
    process.start()
    os.close(write_fd)
    time.sleep(after_s)  # not a wait: the random moment of the kill
    if process.is_alive():
        os.kill(process.pid, signal.SIGKILL)
    process.join()
    announced = b""
    while chunk := os.read(read_fd, 65536):
        announced += chunk
    os.close(read_fd)
    return {int(x) for x in announced.split()}


@pytest.mark.slow
@pytest.mark.parametrize("adaptive", [
    "{procedure: quest_plus, start: 0.5, min: 0, max: 1.5, grid_points: 51}",
    "{procedure: staircase, rule: weighted, target: 0.75, start: 1.0, min: 0, max: 1.5, step_sizes: [0.1, 0.05]}",
])
def test_sigkill_gives_the_levels_of_an_uninterrupted_run(tmp_path: Path, adaptive: str) -> None:
    protocol = adaptive_detection(tmp_path, adaptive, 12, backs="[1, 3]")
    n = 24
    reference = tmp_path / "reference"
    assert cli_main(_args(protocol, reference, 0.0)) == 0
    expected = pd.read_parquet(SessionPaths(reference, "detection", "K1", 1).trials_parquet)
    assert len(expected) == n

    data = tmp_path / "killed"
    paths = SessionPaths(data, "detection", "K1", 1)
    rng = random.Random(4321)
    kills, announced_total, progressed = 0, set(), 0
    while kills < 12 or (kills < 60 and len(announced_total) < n // 2):
        announced = _kill_once(_args(protocol, data, 0.01), rng.uniform(0.05, 0.6))
        kills += 1
        progressed += bool(announced - announced_total)
        announced_total |= announced
        if len(announced_total) >= n:
            break
    assert kills >= 10 and progressed >= 3, (kills, progressed)
    assert cli_main(_args(protocol, data, 0.0)) == 0  # resume to the end
    final = pd.read_parquet(paths.trials_parquet)
    assert final["trial"].tolist() == list(range(n))
    pd.testing.assert_frame_equal(final[COMPARED].reset_index(drop=True), expected[COMPARED].reset_index(drop=True),
                                  check_dtype=False)
