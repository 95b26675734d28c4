"""Every display x response combination `psyop run --help` lists either runs or is refused at start with a hint
that works (issue 45): one real `psyop run` per pair, a two-trial protocol whose response phase times out, so
a pair runs to completion whether or not anybody answers (the live sources are real and silent: the terminal is a
pty, the response box a pty device, the controllers Monado's remote driver). Headless pairs run everywhere; the
window's under a private Xvfb, the headset's on the Monado runtime (skipped, saying why, without them)."""

from __future__ import annotations

import os
import pty
import subprocess
import sys
import tty
from collections.abc import Iterator
from pathlib import Path

import pandas as pd
import pytest

from protocol_texts import TWO_INTERVAL_TAIL, disc_on_wall_head
from psyop.run.backends import backends

from test_controls_terminal import _controlling_tty
from test_window_escape import private_keyboard

ROOT = Path(__file__).resolve().parents[2]
XR_DIR = Path(__file__).parents[1] / "devices" / "xr"

PROTOCOL = disc_on_wall_head("pairs") + TWO_INTERVAL_TAIL.replace("duration_s: 1}", "duration_s: 0.1}").replace(
    "{kind: response, expected_s: 1}",  # a short prompt: Monado's 320x240 view fits 8 lines of legible text
    "{kind: response, expected_s: 0.2, timeout_s: 0.3, prompt: '1 or 2?'}") + """observer:
  kind: psychometric_2afc
  level_column: level_D
  threshold_D: 0.36
  width_D: 0.2
  lapse: 0.02
"""

#: the pairs refused at start, and the display their hint names (its pair with the same responses runs)
REFUSED = {("headless", "openxr"): "--display openxr", ("window", "openxr"): "--display openxr"}
DISPLAYS = [b.name for b in backends("display")]
RESPONSES = [b.name for b in backends("responses")]
PAIRS = [(d, r) for d in DISPLAYS for r in RESPONSES]


def test_the_table_covers_every_registered_pair_and_each_refusal_hint_names_a_running_pair() -> None:
    from psyop.cli.run import MIRROR_WIDTH_PX
    from psyop.devices.experimenter import MIRROR_WIDTH_PX as WINDOW_DEFAULT_PX

    assert MIRROR_WIDTH_PX == WINDOW_DEFAULT_PX  # --mirror-width-px's default is the window's
    assert set(REFUSED) <= set(PAIRS) and len(PAIRS) == len(DISPLAYS) * len(RESPONSES) >= 15
    for (display, responses), hint in REFUSED.items():
        assert (hint.split()[-1], responses) in PAIRS and (hint.split()[-1], responses) not in REFUSED


@pytest.fixture(scope="module")
def x_display() -> Iterator[str]:
    with private_keyboard() as keyboard:
        yield keyboard.display


def _env(display: str, request: pytest.FixtureRequest, tmp_path: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    if display == "window":
        env["DISPLAY"] = request.getfixturevalue("x_display")
    if display == "openxr":
        sys.path.insert(0, str(XR_DIR))
        from monado import runtime_env  # skips without the runtime

        env = {k: v for k, v in runtime_env(tmp_path).items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    return env


def _run(cmd: list[str], env: dict[str, str], responses: str, tmp_path: Path) -> subprocess.CompletedProcess:
    """The pair's session: the terminal a pty for keyboard, a silent pty device for the response box, Monado's
    remote driver (controllers on, no button pressed) for the headset's controllers."""
    if responses == "openxr":
        from monado import RemoteState, run_driven

        return run_driven(cmd, tmp_path, RemoteState(), lambda state, elapsed_s: None, timeout_s=120)
    master, slave = pty.openpty()
    try:
        if responses == "serial":
            tty.setraw(slave)
            cmd = [c if c != "serial" else f"serial:{os.ttyname(slave)}" for c in cmd]
            return subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True, timeout=120,
                                  stdin=subprocess.DEVNULL)
        if responses == "keyboard":
            return subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True, timeout=120, stdin=slave,
                                  start_new_session=True, preexec_fn=_controlling_tty)
        return subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True, timeout=120,
                              stdin=subprocess.DEVNULL)
    finally:
        os.close(master)
        os.close(slave)


@pytest.mark.parametrize(("display", "responses"), PAIRS)
def test_each_display_and_response_pair_runs_or_is_refused_with_a_working_hint(
        display: str, responses: str, tmp_path: Path, request: pytest.FixtureRequest) -> None:
    protocol = tmp_path / "pairs.yaml"
    protocol.write_text(PROTOCOL)
    live = display == "openxr" or responses in ("keyboard", "serial", "openxr")
    cmd = [sys.executable, "-m", "psyop", "run", str(protocol), "--participant", "P1", "--data",
           str(tmp_path / "data"), "--display", display, "--responses", responses, "--clock",
           "real" if live else "virtual", "--no-progress"]
    cmd += ["--window-scale", "0.25"] if display == "window" else []
    cmd += ["--pose", "openxr"] if display == "openxr" else []
    cmd += ["--render", "cameras"] if display == "headless" else []  # no screen: a software ray-cast costs seconds
    if (display, responses) in REFUSED:  # refused before anything is built or written
        done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
        lines = done.stderr.strip().splitlines()
        assert done.returncode == 2 and len(lines) == 1 and "Traceback" not in done.stderr, done.stderr
        assert REFUSED[display, responses] in lines[0], lines
        assert not (tmp_path / "data").exists()
        return
    done = _run(cmd, _env(display, request, tmp_path), responses, tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    trials = pd.read_parquet(tmp_path / "data" / "pairs" / "sub-P1" / "ses-1" / "trials.parquet")
    assert sorted(trials["trial"]) == [0, 1]
    if responses == "sim":
        assert trials["response"].isin(["1", "2"]).all()
    else:  # nobody answered: every response phase ran to its timeout
        assert (trials["response"] == "timeout").all(), trials["response"].tolist()
