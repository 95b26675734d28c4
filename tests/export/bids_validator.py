"""The official BIDS validator (bids-validator-deno, the test extra) as the export tests call it: one
command, one JSON report, or a skip that says why it cannot run here."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest


def validator_command() -> list[str]:
    """The validator command, or a skip that says why it cannot run here."""
    if importlib.util.find_spec("bids_validator_deno") is None:
        pytest.skip("bids-validator-deno is not installed (pip install -e '.[test]' installs it)")
    exe = Path(sys.executable).with_name("bids-validator-deno")
    command = [str(exe)] if exe.exists() else [sys.executable, "-c", "from bids_validator_deno import cli; cli()"]
    probe = subprocess.run([*command, "--version"], capture_output=True, text=True, timeout=120)
    if probe.returncode != 0:
        pytest.skip(f"bids-validator-deno cannot run here (exit {probe.returncode}): {probe.stderr.strip()[:200]}")
    return command


def validate(root: Path) -> tuple[int, Counter]:
    """The validator's exit code on ``root`` and its issues counted by (severity, code)."""
    result = subprocess.run([*validator_command(), str(root), "--format", "json", "--max-rows", "-1"],
                            capture_output=True, text=True, timeout=600)
    report = json.loads(result.stdout)
    return result.returncode, Counter((i["severity"], i["code"]) for i in report["issues"]["issues"])
