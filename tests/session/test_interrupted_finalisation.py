"""A kill during finalisation: `psyop sessions` (and so `make figures`) said a parquet file 'has no
SHA-256 in session.json ... delete it and run psyop recover'. It is an unfinished finalisation:
reported as incomplete with the command that finishes it, and nothing tells the user to delete data."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from psyop.errors import UserError
from psyop.statistics.dataset import load_dataset
from session_helpers import small_protocol

REPO = Path(__file__).resolve().parents[2]

#: a `psyop run` killed (os._exit, as SIGKILL: no cleanup) right after the parquet files were written,
#: before session.json recorded their SHA-256
KILLED_IN_FINALISATION = """
import os, sys
import psyop.session.log.store as store
def killed(*args, **kwargs):
    os._exit(9)
store.record_finalised = killed
from psyop.cli import main
sys.exit(main(sys.argv[1:]))
"""


def _psyop(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "psyop", *argv], capture_output=True, text=True, cwd=REPO)


def test_an_unfinished_finalisation_is_incomplete_and_recover_finishes_it(tmp_path: Path) -> None:
    protocol = small_protocol(tmp_path, "ordinal", 1)
    data = tmp_path / "data"
    run = ["run", str(protocol), "--participant", "K1", "--data", str(data), "--no-progress", "--render", "cameras"]
    killed = subprocess.run([sys.executable, "-c", KILLED_IN_FINALISATION, *run], capture_output=True, text=True,
                            cwd=REPO)
    assert killed.returncode == 9, killed.stderr
    session = next(data.glob("*/sub-K1/ses-1"))
    assert (session / "trials.parquet").is_file()
    assert "trials.parquet" not in json.loads((session / "session.json").read_text()).get("finalised_files", {})

    listed = _psyop("sessions", str(data))
    assert listed.returncode == 0, listed.stderr
    assert "1 incomplete" in listed.stdout and "psyop recover" in listed.stdout and str(session) in listed.stdout
    assert "delete" not in listed.stdout + listed.stderr

    with pytest.raises(UserError) as refused:  # the analysis does not read half-sealed files: it says how to finish
        load_dataset(data, session.parent.parent.name)
    assert f"psyop recover {session}" in str(refused.value) and "delete" not in str(refused.value)

    recovered = _psyop("recover", str(session))
    assert recovered.returncode == 0, recovered.stderr
    listed = _psyop("sessions", str(data))
    assert listed.returncode == 0 and "incomplete" not in listed.stdout and "recover" not in listed.stdout, listed.stdout


#: `psyop recover` killed the same way, right after it wrote the parquet files
KILLED_IN_RECOVER = KILLED_IN_FINALISATION


def test_second_kill_in_finalisation_is_incomplete_and_finished_by_recover(tmp_path: Path) -> None:
    """A run killed mid-session (session.json: status running, no run end), then a `psyop recover` killed
    while it wrote the parquet files: unfinished_finalisation saw no ended run, so `psyop sessions` exited 2
    with 'trials.parquet has no SHA-256 in session.json ... delete it and run psyop recover'."""
    protocol = small_protocol(tmp_path, "ordinal", 1)
    data = tmp_path / "data"
    run = _psyop("run", str(protocol), "--participant", "K2", "--data", str(data), "--no-progress",
                 "--render", "cameras")
    assert run.returncode == 0, run.stderr
    session = next(data.glob("*/sub-K2/ses-1"))
    # the state of a run killed after its last trial was logged, before it ended (no cleanup ran)
    meta = json.loads((session / "session.json").read_text())
    meta["status"] = "running"
    for key in ("finalised", "finalised_files", "summary"):
        meta.pop(key, None)
    for key in ("ended", "status"):
        meta["runs"][-1].pop(key, None)
    (session / "session.json").write_text(json.dumps(meta))
    for name in ("trials.parquet", "frames.parquet", "gaze.parquet"):
        (session / name).unlink()

    killed = subprocess.run([sys.executable, "-c", KILLED_IN_RECOVER, "recover", str(session)], capture_output=True,
                            text=True, cwd=REPO)
    assert killed.returncode == 9, killed.stderr
    assert (session / "trials.parquet").is_file()
    assert "trials.parquet" not in json.loads((session / "session.json").read_text()).get("finalised_files", {})

    listed = _psyop("sessions", str(data))
    assert listed.returncode == 0, listed.stderr
    assert "1 incomplete" in listed.stdout and f"psyop recover {session}" in listed.stdout, listed.stdout
    assert "delete" not in listed.stdout + listed.stderr
    with pytest.raises(UserError) as refused:
        load_dataset(data, session.parent.parent.name)
    assert f"psyop recover {session}" in str(refused.value) and "delete" not in str(refused.value)

    recovered = _psyop("recover", str(session))
    assert recovered.returncode == 0, recovered.stderr
    listed = _psyop("sessions", str(data))
    assert listed.returncode == 0 and "incomplete" not in listed.stdout and "recover" not in listed.stdout, listed.stdout
    assert "1 real" in listed.stdout or "1 simulated" in listed.stdout, listed.stdout
