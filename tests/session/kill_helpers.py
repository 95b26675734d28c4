"""Kill a forked `psyop run` at a chosen moment and learn which trials it had made durable.

Shared by the crash-safety tests of plain and adaptive sessions. The child announces each
trial on a pipe only *after* its durable append returned, so the parent knows exactly which
trials were recorded before the SIGKILL.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import time
from pathlib import Path

from psyop.cli import main as cli_main


def run_args(protocol: Path, data: Path, participant: str, seed: int, delay_s: float) -> list[str]:
    """`psyop run` arguments of a headless virtual-clock session with a real delay per phase."""
    return ["run", str(protocol), "--participant", participant, "--seed", str(seed), "--data", str(data),
            "--clock", "virtual", "--no-progress", "--phase-delay-s", str(delay_s), "--render", "cameras"]


def _child(argv: list[str], announce_fd: int) -> None:
    """Run `psyop run` in this (forked) process, announcing each durable trial."""
    from psyop.session.log import store

    original = store.SessionStore.append_trial

    def append_and_announce(self, row, frames, gaze=None):  # type: ignore[no-untyped-def]
        original(self, row, frames, gaze)
        os.write(announce_fd, f"{int(row['trial'])}\n".encode())

    store.SessionStore.append_trial = append_and_announce  # instrumentation only, after the real append
    os._exit(cli_main(argv))


def kill_once(argv: list[str], after_s: float, after_trials: int = 0, deadline_s: float = 120.0) -> set[int]:
    """Start `psyop run argv` in a forked child and SIGKILL it ``after_s`` after it announced
    ``after_trials`` durable trials (0: after its start); the trials it announced as durable.

    Waiting for announced trials (polled with a generous deadline) puts the kill inside the
    session however slowly a loaded machine starts the child; ``after_s`` is the random moment."""
    import select

    read_fd, write_fd = os.pipe()
    process = mp.get_context("fork").Process(target=_child, args=(argv, write_fd))
    process.start()
    os.close(write_fd)
    announced = b""
    deadline = time.monotonic() + deadline_s
    while len(announced.split()) < after_trials and process.is_alive() and time.monotonic() < deadline:
        ready, _, _ = select.select([read_fd], [], [], 0.05)
        if ready:
            chunk = os.read(read_fd, 65536)
            if not chunk:
                break
            announced += chunk
    time.sleep(after_s)  # not a wait: the random moment of the kill
    if process.is_alive():
        os.kill(process.pid, signal.SIGKILL)
    process.join()
    while chunk := os.read(read_fd, 65536):
        announced += chunk
    os.close(read_fd)
    return {int(x) for x in announced.split()}
