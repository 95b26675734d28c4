"""Helpers the response-kind tests share (tests/session/test_kind_*.py): a variant of an example protocol, a scripted
key source, a window session typed under Xvfb, frames rendered in one child process, an analysis script's main run
in this process."""

from __future__ import annotations

import importlib
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

REPO = Path(__file__).resolve().parents[2]


def variant(example: Path, tmp_path: Path, *, repetitions: int | None = None, phase_s: float | None = None,
            replace: tuple[tuple[str, str], ...] = (), name: str | None = None) -> Path:
    """A copy of ``example`` with fewer repetitions, every phase ``phase_s`` long, or a few lines replaced."""
    text = example.read_text()
    if repetitions is not None:
        text = re.sub(r"(?m)^(\s*repetitions:)\s*\d+", rf"\g<1> {repetitions}", text)
    if phase_s is not None:
        text = re.sub(r"(duration_s|expected_s):\s*[\d.]+", rf"\g<1>: {phase_s}", text)
    for old, new in replace:
        assert old in text, old
        text = text.replace(old, new)
    path = tmp_path / (name or example.name)
    path.write_text(text)
    return path


class ScriptedKeys:
    """A key source (psyop.devices.responses.keyboard.KeyEvents) that hands out the presses it was given once."""

    def __init__(self, presses: list[tuple[str, float]]) -> None:
        self.presses = presses

    def poll(self) -> list[tuple[str, float]]:
        out, self.presses = self.presses, []
        return out


_WINDOW_SCRIPT = textwrap.dedent(
    """
    from pathlib import Path
    from psyop.protocol import load_protocol
    from psyop.schedule import compile_schedule
    from psyop.run.runner import SessionOptions, run_session
    import psyop.devices.window as window

    typed = window.GlfwWindow.poll
    def poll(self):  # a participant who presses these keys whenever asked
        for key in {keys!r}:
            self.inject_key(key)
        return typed(self)
    window.GlfwWindow.poll = poll
    outcome = run_session(load_protocol(Path({protocol!r})), compile_schedule, SessionOptions(
        participant="W1", data_root=Path({data!r}), clock="real", display="window", responses="keyboard",
        tracker="sim", progress=False, render="auto", window_scale=0.2))
    print(outcome.status)
    """
)


def window_session(protocol: Path, data: Path, keys: list[str]) -> str:
    """Run participant W1 of ``protocol`` in a glfw window under Xvfb with keyboard responses, ``keys`` typed at
    every poll; the session's status (asserting the child process exited 0)."""
    script = _WINDOW_SCRIPT.format(keys=keys, protocol=str(protocol), data=str(data))
    result = subprocess.run(["xvfb-run", "-a", sys.executable, "-c", script], capture_output=True, text=True,
                            timeout=180)
    assert result.returncode == 0, result.stderr[-2000:]
    return result.stdout.split()[-1]


def render_frames(folder: Path, protocol: Path, seed: int, frames: list[tuple[str, int, int]],
                  gaze_deg: str = "15,0") -> None:
    """``psyop render`` of each (file name, trial, interval) with the eye turned to ``gaze_deg`` (15 deg right by
    default), in one child process (the EGL context lives in it)."""
    script = textwrap.dedent(f"""
        from psyop.cli import main
        for name, trial, interval in {frames!r}:
            assert main(["render", {str(protocol)!r}, "--seed", "{seed}", "--trial", str(trial), "--interval",
                         str(interval), "--gaze-deg", "{gaze_deg}", "--out", {str(folder)!r} + "/" + name]) == 0
        """)
    subprocess.run([sys.executable, "-c", script], check=True, cwd=REPO, capture_output=True, timeout=180)


def red_near_centre(png: Path, radius_px: int = 20) -> int:
    """Red pixels within ``radius_px`` of the image centre (where the discs straight ahead of the eye are drawn)."""
    image = np.asarray(Image.open(png).convert("RGB")).astype(int)
    h, w = image.shape[:2]
    yy, xx = np.mgrid[:h, :w]
    near = (yy - h / 2) ** 2 + (xx - w / 2) ** 2 <= radius_px ** 2
    red = (image[..., 0] > 150) & (image[..., 1] < 80) & (image[..., 2] < 80)
    return int((red & near).sum())


def run_analysis(monkeypatch: pytest.MonkeyPatch, script: str, argv: list[str]) -> int:
    """analysis/<script>.py's main, in this process (as make runs it, without the interpreter's start)."""
    monkeypatch.syspath_prepend(str(REPO / "analysis"))
    try:
        return importlib.import_module(script).main(argv)
    finally:
        sys.modules.pop(script, None)
