"""Helpers for session tests: small copies of the real protocols."""

from __future__ import annotations

import re
from pathlib import Path

PROTOCOLS = Path(__file__).resolve().parents[2] / "protocols"


def small_protocol(directory: Path, study: str, repetitions: int = 1) -> Path:
    """A copy of protocols/<study>.yaml with ``repetitions`` per condition (fewer trials)."""
    text = (PROTOCOLS / f"{study}.yaml").read_text()
    text, n = re.subn(r"(?m)^(\s*repetitions:)\s*\d+", rf"\g<1> {repetitions}", text)
    assert n == 1, f"{study}.yaml: no repetitions line to shrink"
    # files the protocol names relative to protocols/ (the egocentric room's model) from the copy's folder
    text = re.sub(r"(?m)^(\s*file:\s*)(\.\./\S+)", lambda m: m.group(1) + str((PROTOCOLS / m.group(2)).resolve()), text)
    path = directory / f"{study}_small.yaml"
    path.write_text(text)
    return path


def fast_protocol(directory: Path, study: str, repetitions: int = 1, phase_s: float = 0.05) -> Path:
    """Like :func:`small_protocol`, with every phase shortened to ``phase_s`` (real-clock tests)."""
    path = small_protocol(directory, study, repetitions)
    text = re.sub(r"(?m)^(\s*(?:-\s*)?(?:duration_s|expected_s|min_duration_s):)\s*[\d.]+", rf"\g<1> {phase_s}", path.read_text())
    path.write_text(text)
    return path


def wait_until(predicate, *, timeout_s: float = 60.0, what: str = "condition", poll_s: float = 0.01):
    """Poll ``predicate`` until it returns a truthy value (returned) or fail after a generous
    ``timeout_s``. Tests wait for an event this way, never with a fixed sleep, so a loaded
    machine makes them slower, not red."""
    import time

    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(poll_s)
