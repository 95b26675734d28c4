"""The psyop command itself: help, version, and errors without tracebacks."""

from __future__ import annotations

import subprocess
import sys

import psyop
from psyop.cli import build_parser, main


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "psyop", *args], capture_output=True, text=True, timeout=120)


def test_version_matches_package_metadata() -> None:
    result = run_cli("--version")
    assert result.returncode == 0
    assert result.stdout.strip() == f"psyop {psyop.__version__}"
    assert psyop.__version__ != "0.0.0+unknown"


def test_help_lists_every_discovered_command() -> None:
    result = run_cli("--help")
    assert result.returncode == 0
    parser = build_parser()
    commands = next(a for a in parser._actions if a.dest == "command").choices  # noqa: SLF001
    for name in commands:
        assert name in result.stdout


def test_unknown_command_exits_2_without_traceback() -> None:
    result = run_cli("no-such-command")
    assert result.returncode == 2
    assert "Traceback" not in result.stderr


def test_no_command_prints_help(capsys) -> None:
    assert main([]) == 0
    assert "usage: psyop" in capsys.readouterr().out
