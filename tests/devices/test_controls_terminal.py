"""The terminal's keys in a headless session (psyop.devices.responses.terminal, psyop.session.controls): a real
`psyop run --display headless --responses keyboard --clock real` whose standard input is a pty (its controlling
terminal, as a shell gives it), keys typed into the pty's other end. Answers are recorded; ``c`` without a gaze
validation says so once; ``p`` pauses between trials and ``p`` resumes, logged in events.parquet; Escape ends the
session with exit 130, the trial in progress discarded, and the same command resumes it. A pause on the virtual
clock leaves the session clock where it was (the same run without the pause, same seed, compared)."""

from __future__ import annotations

import fcntl
import io
import json
import os
import pty
import signal
import subprocess
import sys
import termios
import threading
from pathlib import Path

import pandas as pd
import pytest

from psyop.devices.responses.terminal import decode
from psyop.session.log.layout import session_paths
from psyop.session.log.store import recover_tables

from session_helpers import fast_protocol, small_protocol, wait_until
from unshipped_protocols import write

ROOT = Path(__file__).resolve().parents[2]


def _controlling_tty() -> None:  # in the child, after setsid: standard input becomes its controlling terminal
    fcntl.ioctl(0, termios.TIOCSCTTY, 0)


def _controlling_tty_sigint_ignored() -> None:  # as a background job's child: SIGINT ignored, kept through exec
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _controlling_tty()


class TerminalSession:
    """`psyop run ARGS` with a pty for its terminal; stderr collected line by line. ``sigint_ignored``: the session
    inherits SIGINT ignored, as a process started by a background job (or a harness that ignores it) does."""

    def __init__(self, args: list[str], sigint_ignored: bool = False) -> None:
        self.master, slave = pty.openpty()
        self.proc = subprocess.Popen([sys.executable, "-m", "psyop", "run", *args], cwd=ROOT, stdin=slave,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                     start_new_session=True,
                                     preexec_fn=_controlling_tty_sigint_ignored if sigint_ignored else _controlling_tty,
                                     env={**os.environ, "PYTHONFAULTHANDLER": "1"})  # SIGABRT: every thread's stack
        os.close(slave)
        self.err: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.err.append(line.rstrip("\n"))

    def type(self, keys: bytes) -> None:
        os.write(self.master, keys)

    def said(self, text: str) -> bool:
        assert self.proc.poll() is None or any(text in line for line in self.err), "\n".join(self.err)
        return any(text in line for line in self.err)

    def finish(self) -> tuple[int, str]:
        try:
            rc = self.proc.wait(timeout=120)
        except subprocess.TimeoutExpired:  # where each thread of the session waits, on its stderr, then it ends
            self.proc.send_signal(signal.SIGABRT)
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=30)
            self._reader.join(timeout=10)
            raise AssertionError("the session did not end:\n" + "\n".join(self.err)) from None
        finally:
            os.close(self.master)
        self._reader.join(timeout=30)
        return rc, "\n".join(self.err)


def _recorded(data: Path) -> int:
    trials = recover_tables(session_paths(data, "detection", "T1", 1))[0]
    return 0 if trials is None else len(trials)


def test_decode_names_the_keys_a_terminal_sends() -> None:
    assert decode("2Y\x1b[A\x1bOB\x1b[C\x1b[D\n\r ") == ["2", "y", "up", "down", "right", "left", "enter", "enter",
                                                           "space"]
    assert decode("\x1b") == ["escape"] and decode("p\x1bc") == ["p", "escape", "c"]


def test_terminal_keys_answer_pause_and_end_a_headless_session_which_resumes(tmp_path: Path) -> None:
    """The first session inherits SIGINT ignored (a background job's child): Escape still ends it (before the
    terminal's keys handled SIGINT for the session, the session went on after Escape); the resumed one does not."""
    protocol = fast_protocol(tmp_path, "detection", 1, 0.03)
    data = tmp_path / "data"
    args = [str(protocol), "--participant", "T1", "--data", str(data), "--display", "headless", "--responses",
            "keyboard", "--clock", "real", "--no-progress"]
    session = TerminalSession(args, sigint_ignored=True)
    wait_until(lambda: session.said("question for the participant"), what="the session to start")

    def answered() -> int:  # the participant types '2' until a trial is recorded
        session.type(b"2")
        return _recorded(data)

    wait_until(answered, timeout_s=120, what="a trial answered with '2' in the terminal", poll_s=0.05)
    session.type(b"c")  # no gaze validation: said once, at the next trial boundary
    session.type(b"p")  # a pause at the next trial boundary: the trial in progress is answered first

    def paused() -> bool:
        if session.said("paused before trial"):
            return True
        session.type(b"2")
        return False

    wait_until(paused, timeout_s=120, what="the pause to begin", poll_s=0.05)
    n_paused = _recorded(data)
    session.type(b"p")
    wait_until(lambda: session.said("resumed after"), what="the pause to end")
    session.type(b"\x1b")  # Escape, alone: during the next trial (no answer typed)
    rc, err = session.finish()
    assert rc == 130, err
    assert "Traceback" not in err, err
    end = [line for line in err.splitlines() if line.startswith("psyop run: interrupted:")]
    assert len(end) == 1 and "Escape pressed in the terminal" in end[0] and "discarded" in end[0], err
    assert sum("c (recalibrate) does nothing" in line for line in err.splitlines()) == 1, err
    directory = session_paths(data, "detection", "T1", 1).directory
    meta = json.loads((directory / "session.json").read_text())
    first = pd.read_parquet(directory / "trials.parquet")
    assert meta["status"] == "incomplete" and len(first) == n_paused and (first["response"] == "2").all()
    events = pd.read_parquet(directory / "events.parquet")
    pause = events[events["screen"] == "pause"].iloc[0]
    assert pause["before_trial"] == n_paused and pause["trials_done"] == n_paused
    assert pause["duration_s"] > 0 and pause["end_s"] >= pause["start_s"] and pause["ended_by"] == "key in the terminal"
    recalibrate = events[events["screen"] == "recalibrate"]
    assert len(recalibrate) == 1 and "no gaze_validation" in recalibrate["text"].iloc[0]
    # the same command resumes, answered in the terminal to the end
    session = TerminalSession(args)

    def finished() -> bool:
        if session.proc.poll() is not None:
            return True
        session.type(b"2")
        return False

    wait_until(finished, timeout_s=300, what="the resumed session to finish", poll_s=0.05)
    rc, err = session.finish()
    assert rc == 0, err
    trials = pd.read_parquet(directory / "trials.parquet")
    assert sorted(trials["trial"]) == list(range(int(meta["n_trials_scheduled"])))


class _Stderr(io.StringIO):
    """stderr that types ``p`` into the terminal when the session says it paused (the participant resumes)."""

    def __init__(self, master: int) -> None:
        super().__init__()
        self.master = master

    def write(self, text: str) -> int:
        if "paused before trial" in text:
            os.write(self.master, b"p")
        return super().write(text)


def _in_process_run(protocol: Path, data: Path, typed_ahead: bytes, monkeypatch: pytest.MonkeyPatch) -> str:
    """A simulated session on the virtual clock in this process, its terminal a pty into which ``typed_ahead`` is
    typed before it starts (and ``p`` again whenever it says it paused); its stderr."""
    from psyop.protocol import load_protocol
    from psyop.run.runner import SessionOptions, run_session
    from psyop.schedule import compile_schedule

    master, slave = pty.openpty()
    stderr = _Stderr(master)
    try:
        monkeypatch.setattr(sys, "stdin", os.fdopen(slave, "r", closefd=False))
        monkeypatch.setattr(sys, "stderr", stderr)
        os.write(master, typed_ahead)
        options = SessionOptions(participant="V1", data_root=data, progress=False, terminal_keys=True, fsync=False)
        outcome = run_session(load_protocol(protocol), compile_schedule, options)
    finally:
        monkeypatch.undo()
        os.close(master)
        os.close(slave)
    assert outcome.status == "complete", stderr.getvalue()
    return stderr.getvalue()


def _virtual_run(protocol: Path, data: Path, pause_at_start: bool, monkeypatch: pytest.MonkeyPatch) -> pd.DataFrame:
    """:func:`_in_process_run` of detection; with ``pause_at_start``, ``p`` typed ahead (a pause before trial 0)."""
    _in_process_run(protocol, data, b"p" if pause_at_start else b"", monkeypatch)
    directory = session_paths(data, "detection", "V1", 1).directory
    if pause_at_start:
        events = pd.read_parquet(directory / "events.parquet")
        pause = events[events["screen"] == "pause"]
        assert len(pause) == 1 and pause["before_trial"].iloc[0] == 0, events
        assert pause["start_s"].iloc[0] == pause["end_s"].iloc[0] and pause["duration_s"].iloc[0] > 0
    return pd.read_parquet(directory / "trials.parquet")


def test_a_pause_on_the_virtual_clock_leaves_the_session_clock_unmoved(tmp_path: Path,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    protocol = small_protocol(tmp_path, "detection", 1)
    plain = _virtual_run(protocol, tmp_path / "plain", False, monkeypatch)
    paused = _virtual_run(protocol, tmp_path / "paused", True, monkeypatch)
    columns = ["trial", "trial_start_s", "trial_end_s", "response"]
    pd.testing.assert_frame_equal(paused[columns].sort_values("trial").reset_index(drop=True),
                                  plain[columns].sort_values("trial").reset_index(drop=True), check_exact=True)


def test_c_runs_the_protocols_gaze_validation_at_the_next_trial_boundary(tmp_path: Path,
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    protocol = write(tmp_path, "validated", repetitions=1)
    err = _in_process_run(protocol, tmp_path / "data", b"c", monkeypatch)
    assert "recalibrating before trial 0 (c pressed in the terminal)" in err, err
    directory = session_paths(tmp_path / "data", "validated", "V1", 1).directory
    validation = pd.read_parquet(directory / "validation.parquet")
    assert "recalibrate" in set(validation["when"]) and (validation.loc[validation["when"] == "recalibrate",
                                                                         "before_trial"] == 0).all()
    events = pd.read_parquet(directory / "events.parquet")
    row = events[events["screen"] == "recalibrate"].iloc[0]
    assert "gaze validation run" in row["text"] and row["end_s"] > row["start_s"] and row["before_trial"] == 0


def test_keyboard_responses_without_a_terminal_or_window_are_refused_with_the_ways_that_work(tmp_path: Path) -> None:
    protocol = fast_protocol(tmp_path, "detection", 1, 0.03)
    done = subprocess.run([sys.executable, "-m", "psyop", "run", str(protocol), "--participant", "T1", "--data",
                           str(tmp_path / "data"), "--display", "headless", "--responses", "keyboard", "--clock",
                           "real", "--no-progress"], cwd=ROOT, capture_output=True, text=True, timeout=120,
                          stdin=subprocess.DEVNULL)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    refusal = [line for line in lines if "error" in line]
    assert len(refusal) == 1 and "run it from a terminal" in refusal[0] and "--display window" in refusal[0]
    assert "--experimenter-window" in refusal[0], refusal
