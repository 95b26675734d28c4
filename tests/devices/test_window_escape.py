"""Escape in a real session window (issue 45 item 3): `psyop run --display window` under a private Xvfb server,
with real key events sent to the X server (XTest, as xdotool does). Escape ends the session as Ctrl-C does: exit
130, the trial in progress discarded, nothing recorded lost, and the same command resumes it. Escape used to raise
KeyboardInterrupt inside glfw's ctypes key callback, where Python prints "Exception ignored on calling ctypes
callback function" and the session runs on."""

from __future__ import annotations

import ctypes
import ctypes.util
import json
import os
import shutil
import subprocess
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pandas as pd
import pytest

from psyop.session.log.layout import session_paths
from psyop.session.log.store import recover_tables

from session_helpers import fast_protocol, wait_until

ROOT = Path(__file__).resolve().parents[2]
XK_ESCAPE, XK_2 = 0xFF1B, 0x32


def _xtest() -> tuple[ctypes.CDLL, ctypes.CDLL] | None:
    """libX11 and libXtst, typed for the few calls sending a key press; None where either is missing."""
    try:
        x11 = ctypes.CDLL(ctypes.util.find_library("X11") or "libX11.so.6")
        xtst = ctypes.CDLL(ctypes.util.find_library("Xtst") or "libXtst.so.6")
    except OSError:
        return None
    x11.XOpenDisplay.restype, x11.XOpenDisplay.argtypes = ctypes.c_void_p, [ctypes.c_char_p]
    x11.XKeysymToKeycode.restype, x11.XKeysymToKeycode.argtypes = ctypes.c_ubyte, [ctypes.c_void_p, ctypes.c_ulong]
    x11.XFlush.argtypes = x11.XCloseDisplay.argtypes = [ctypes.c_void_p]
    xtst.XTestFakeKeyEvent.argtypes = [ctypes.c_void_p, ctypes.c_uint, ctypes.c_int, ctypes.c_ulong]
    return x11, xtst


class Keyboard:
    """Key presses on one X server, through one connection held for the test (opened once: a server socket
    another process's X server might replace later is never looked up again)."""

    def __init__(self, display: str) -> None:
        libs = _xtest()
        assert libs is not None
        self._x11, self._xtst = libs
        self.display = display
        self._dpy = self._x11.XOpenDisplay(display.encode())
        assert self._dpy, f"cannot open X display {display}"

    def press(self, keysym: int) -> None:
        """Press and release one key (it goes to the focused window: the session's)."""
        code = self._x11.XKeysymToKeycode(self._dpy, keysym)
        self._xtst.XTestFakeKeyEvent(self._dpy, code, 1, 0)
        self._xtst.XTestFakeKeyEvent(self._dpy, code, 0, 0)
        self._x11.XFlush(self._dpy)

    def close(self) -> None:
        self._x11.XCloseDisplay(self._dpy)


def _start_xvfb(xvfb: str) -> tuple[subprocess.Popen[bytes], Keyboard] | None:
    """Xvfb on a display number of its own (not :0, which `xvfb-run -a` in a parallel test may take over), and a
    connection to it; None when no server came up."""
    for attempt in range(5):
        display = f":{100 + (os.getpid() * 7 + attempt * 131) % 800}"
        proc = subprocess.Popen([xvfb, display, "-screen", "0", "640x480x24", "-nolisten", "tcp"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            keyboard = wait_until(lambda: proc.poll() is None and _connect(display), timeout_s=30,
                                  what=f"Xvfb on {display}", poll_s=0.05)
            return proc, keyboard
        except AssertionError:
            proc.kill()
            proc.wait(timeout=10)
    return None


def _connect(display: str) -> Keyboard | None:
    try:
        return Keyboard(display)
    except AssertionError:
        return None


@contextmanager
def private_keyboard() -> Iterator[Keyboard]:
    """A private Xvfb server (key presses reach this test's windows only) and its XTest keyboard, stopped on exit;
    skips the test where Xvfb or libXtst is missing or no server comes up."""
    xvfb = shutil.which("Xvfb")
    if xvfb is None or _xtest() is None:
        pytest.skip("needs Xvfb and libXtst (apt-get install xvfb libxtst6)")
    started = _start_xvfb(xvfb)
    if started is None:
        pytest.skip("Xvfb did not start")
    proc, keyboard = started
    try:
        yield keyboard
    finally:
        keyboard.close()
        proc.terminate()
        proc.wait(timeout=10)


@pytest.fixture(scope="module")
def x_server() -> Iterator[tuple[str, Keyboard]]:
    """A private Xvfb server (the key presses must reach this test's window only); its keyboard."""
    with private_keyboard() as keyboard:
        yield keyboard.display, keyboard


class Session:
    """`psyop run --display window --responses keyboard` in the background, its stderr collected."""

    def __init__(self, protocol: Path, data: Path, display: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "psyop", "run", str(protocol), "--participant", "E1", "--data", str(data),
             "--display", "window", "--responses", "keyboard", "--clock", "real", "--no-progress",
             "--window-scale", "0.2"], cwd=ROOT, env=dict(os.environ, DISPLAY=display),
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.err: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.err.append(line.rstrip("\n"))

    def finish(self) -> tuple[int, str]:
        try:
            rc = self.proc.wait(timeout=120)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(timeout=30)
            raise AssertionError("the session did not end:\n" + "\n".join(self.err)) from None
        self._reader.join(timeout=30)
        return rc, "\n".join(self.err)


def _recorded(data: Path) -> int:
    """Trials in the session's log so far (read as `psyop recover` salvages it)."""
    trials = recover_tables(session_paths(data, "detection", "E1", 1))[0]
    return 0 if trials is None else len(trials)


def test_escape_ends_a_window_session_with_exit_130_and_it_resumes(tmp_path: Path,
                                                                   x_server: tuple[str, Keyboard]) -> None:
    display, keyboard = x_server
    protocol = fast_protocol(tmp_path, "detection", 1, 0.03)
    data = tmp_path / "data"
    session = Session(protocol, data, display)
    wait_until(lambda: any("question for the participant" in line for line in session.err) or
               session.proc.poll() is not None, what="the session to start")

    def answered() -> int:  # the participant presses '2' until a trial is recorded
        assert session.proc.poll() is None, "\n".join(session.err)
        keyboard.press(XK_2)
        return _recorded(data)

    wait_until(answered, timeout_s=120, what="a trial answered with '2' in the window", poll_s=0.05)
    keyboard.press(XK_ESCAPE)  # during the next trial's response phase (no more answers come)
    rc, err = session.finish()
    assert rc == 130, err
    assert "Exception ignored" not in err and "Traceback" not in err, err
    end = [line for line in err.splitlines() if line.startswith("psyop run: interrupted:")]
    assert len(end) == 1 and "Escape pressed in the session window" in end[0] and "discarded" in end[0], err
    directory = session_paths(data, "detection", "E1", 1).directory
    meta = json.loads((directory / "session.json").read_text())
    first = pd.read_parquet(directory / "trials.parquet")
    assert meta["status"] == "incomplete" and meta["summary"]["outcome"] == "interrupted"
    n_scheduled = int(meta["n_trials_scheduled"])
    assert 1 <= len(first) < n_scheduled and (first["response"] == "2").all()
    # the same command resumes: answered to the end, the first run's trials kept as they were
    session = Session(protocol, data, display)

    def finished() -> bool:
        if session.proc.poll() is not None:
            return True
        keyboard.press(XK_2)
        return False

    wait_until(finished, timeout_s=300, what="the resumed session to finish", poll_s=0.05)
    rc, err = session.finish()
    assert rc == 0, err
    trials = pd.read_parquet(directory / "trials.parquet")
    assert sorted(trials["trial"]) == list(range(n_scheduled))
    again = trials.set_index("trial").loc[first["trial"], ["trial_start_s", "response", "run"]]
    assert again["trial_start_s"].tolist() == first["trial_start_s"].tolist() and (again["run"] == 0).all()
