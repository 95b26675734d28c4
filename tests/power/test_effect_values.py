"""``psyop power --effect KEY=VALUE``: a value YAML cannot construct (an explicit tag with a bad value) is one
line naming the option, exit 2, never a traceback (issue 31's loose end on explicit YAML tags)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from psyop.errors import UserError
from psyop.power.effects import parse_effects

ROOT = Path(__file__).resolve().parents[2]
BAD_VALUES = ["!!timestamp foo", "!!int x", "!!float x", "!!bool maybe", "!!binary x", "!!set [1]",
              "!!python/name:os.system", "!!omap 3", "[1"]


@pytest.mark.parametrize("value", BAD_VALUES)
def test_a_bad_tagged_value_is_one_message_naming_the_option(value: str) -> None:
    with pytest.raises(UserError, match="--effect 'threshold_slope="):
        parse_effects([f"threshold_slope={value}"])


def test_good_values_are_read_as_yaml() -> None:
    assert parse_effects(["threshold_slope=0.05", "observer.lapse=!!float 0.02"]) == (
        ("threshold_slope", 0.05), ("lapse", 0.02))


def test_the_command_ends_in_one_line_and_exit_2() -> None:
    run = subprocess.run([sys.executable, "-m", "psyop", "power", str(ROOT / "protocols" / "detection.yaml"),
                          "--effect", "threshold_slope=!!timestamp foo"], capture_output=True, text=True, cwd=ROOT)
    assert run.returncode == 2, run.stderr
    assert "Traceback" not in run.stderr and "--effect" in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1, run.stderr
