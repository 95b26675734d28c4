"""Two maintenance commands at once: a session another process is finishing is reported as such,
not as a failure, and concurrent `psyop simulate` runs skip the sessions in use and finish the rest."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from psyop.cli import main as cli_main
from psyop.session.lock import SessionInUse, SessionLock
from psyop.session.log.layout import SessionPaths
from session_helpers import small_protocol

SEED = 5


def test_recover_leaves_a_session_another_process_holds(tmp_path: Path, capsys) -> None:
    protocol = small_protocol(tmp_path, "detection", 1)
    data = tmp_path / "data"
    for participant in ("A1", "B1"):
        assert cli_main(["run", str(protocol), "--participant", participant, "--seed", str(SEED), "--data", str(data),
                         "--clock", "virtual", "--no-progress", "--render", "cameras"]) == 0
        paths = SessionPaths(data, "detection", participant, 1)
        meta = json.loads(paths.metadata.read_text())
        paths.metadata.write_text(json.dumps({**meta, "status": "running"}))  # as a crashed run leaves it
    held = SessionPaths(data, "detection", "B1", 1)
    # the holder is a real other process (flock locks are per open file: this process could not conflict)
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time; from psyop.session.lock import SessionLock; "
                               "SessionLock(sys.argv[1]).acquire('recover'); print('held', flush=True); "
                               "sys.stdin.read()", str(held.lock_file)],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        capsys.readouterr()
        assert cli_main(["recover", str(data)]) == 0
        out = capsys.readouterr()
        assert f"{held.directory}: in use by pid {holder.pid}" in out.out and "left to it" in out.out
        assert "could not be recovered" not in out.err
        assert "15/15 trials, complete" in out.out  # A1, recovered by this process
    finally:
        holder.communicate("", timeout=30)
    try:
        SessionLock(held.lock_file).check_free()
    except SessionInUse:  # pragma: no cover - the holder has exited
        raise AssertionError("the lock outlived its holder") from None


def test_concurrent_simulate_runs_share_the_work(tmp_path: Path) -> None:
    protocols = tmp_path / "protocols"
    protocols.mkdir()
    small_protocol(protocols, "detection", 1)
    data = tmp_path / "data"
    argv = [sys.executable, "-m", "psyop", "simulate", "--data", str(data), "--protocols", str(protocols),
            "--participants", "6", "--jobs", "1"]
    first, second = (subprocess.Popen(argv, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
                     for _ in range(2))
    results = [(p.wait(timeout=600), p.stderr.read()) for p in (first, second)]
    for code, stderr in results:
        assert code == 0, stderr
        assert "Traceback" not in stderr
    for i in range(1, 7):  # every session simulated, by one or the other
        paths = SessionPaths(data, "detection", f"S{i:02d}", 1)
        assert json.loads(paths.metadata.read_text())["status"] == "complete"
