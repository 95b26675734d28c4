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
    commands = next(a for a in parser._actions if a.dest == "command").choices
    for name in commands:
        assert name in result.stdout


def test_unknown_command_exits_2_without_traceback() -> None:
    result = run_cli("no-such-command")
    assert result.returncode == 2
    assert "Traceback" not in result.stderr


def test_no_command_prints_help(capsys) -> None:
    assert main([]) == 0
    assert "usage: psyop" in capsys.readouterr().out


def test_show_prints_both_eyes_pixels_for_a_stereo_protocol_with_their_own_frusta(tmp_path) -> None:
    """A stereo protocol shows each eye its own frustum (here deliberately not mirror images): `psyop show`
    prints the pixel angles of both, not the right eye's only."""
    from pathlib import Path

    text = (Path(__file__).parent.parent / "protocols" / "egocentric.yaml").read_text()
    text = text.replace("  profile: vive_pro ", "  profile: {name: lopsided, width_px: 800, height_px: 800, refresh_hz: 90, "
                        "tan_left: -1.2, tan_right: 0.8, tan_bottom: -1.0, tan_top: 1.0, "
                        "left_tangents: [-0.6, 1.4, -1.0, 1.0]} ", 1)
    assets = Path(__file__).parent.parent / "assets"
    text = text.replace("file: ../assets/", f"file: {assets.resolve()}/")  # the room's model, from tmp_path
    protocol = tmp_path / "stereo.yaml"
    protocol.write_text(text)
    result = run_cli("show", str(protocol))
    assert result.returncode == 0, result.stderr
    left = result.stdout.index("display pixels (lopsided, left eye")
    right = result.stdout.index("display pixels (lopsided, right eye")
    left_block = result.stdout[left:right] if left < right else result.stdout[left:]
    right_block = result.stdout[right:left] if right < left else result.stdout[right:]
    # the straight-ahead pixel sits at a different column in each eye's image
    assert "centre  pixel (480, 400)" in right_block
    assert "centre  pixel (240, 400)" in left_block


def _run_into_closed_pipe(*args: str) -> subprocess.CompletedProcess[bytes]:
    """Run psyop with stdout a pipe whose reader has already gone (as `| head -1` after its line)."""
    import os

    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        return subprocess.run([sys.executable, "-m", "psyop", *args], stdout=write_end, stderr=subprocess.PIPE,
                              timeout=120)
    finally:
        os.close(write_end)


def test_a_closed_pipe_ends_every_command_quietly(tmp_path) -> None:
    """`psyop show P | head -1`: no "error: Broken pipe", no traceback, exit 0 or 141 (128 + SIGPIPE), as cat."""
    from pathlib import Path

    protocols = Path(__file__).parent.parent / "protocols"
    for args in (("show", str(protocols / "egocentric.yaml")), ("schema",), ("validate", str(protocols / "detection.yaml")),
                 ("sessions", str(tmp_path)), ("studies", str(tmp_path)), ("--help",), ("show", "--help")):
        result = _run_into_closed_pipe(*args)
        assert result.returncode in (0, 141), (args, result.returncode, result.stderr)
        assert result.stderr.decode() == "", (args, result.stderr)
