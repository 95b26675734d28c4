"""data/ read defensively: `psyop sessions` (make figures' first step) and the loader accept only
regular files within size limits, refuse a session reached twice through a link, never hang on a
FIFO or a link to /dev/zero, and decide simulated or real from records a deleted session.json
does not take away (the finalised trials.parquet, the log's own header).

Real links and FIFOs; each command is a real child process with a deadline.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from psyop.cli import main as cli_main
from psyop.errors import UserError
from psyop.session.log.layout import SessionPaths, write_dataset_description
from psyop.statistics.dataset import load_dataset

SEED = 3


def _run(protocol: Path, data: Path, participant: str) -> SessionPaths:
    assert cli_main(["run", str(protocol), "--participant", participant, "--seed", str(SEED), "--data", str(data),
                     "--clock", "virtual", "--no-progress", "--render", "cameras"]) == 0
    return SessionPaths(data, "detection", participant, 1)


@pytest.fixture(scope="module")
def two_sessions(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from session_helpers import small_protocol

    root = tmp_path_factory.mktemp("hostile")
    protocol = small_protocol(root, "detection", 1)
    data = root / "data"
    for participant in ("A1", "B1"):
        _run(protocol, data, participant)
    return data


@pytest.fixture
def data(two_sessions: Path, tmp_path: Path) -> Path:
    copy = tmp_path / "data"
    shutil.copytree(two_sessions, copy, symlinks=True)
    return copy


def _sessions(data: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "psyop", "sessions", str(data)], capture_output=True, text=True,
                          timeout=120)


def _refused(done: subprocess.CompletedProcess[str], *needles: str) -> None:
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr, done.stderr
    for needle in needles:
        assert needle in done.stderr, done.stderr


def _replace(path: Path, make: object) -> None:
    path.unlink()
    make(path)  # type: ignore[operator]


@pytest.mark.parametrize("name", ["session.json", "trials.parquet"])
@pytest.mark.parametrize("kind", ["/dev/zero link", "FIFO"])
def test_a_fifo_or_device_is_refused_without_hanging(data: Path, name: str, kind: str) -> None:
    target = data / "detection" / "sub-B1" / "ses-1" / name
    _replace(target, (lambda p: p.symlink_to("/dev/zero")) if kind == "/dev/zero link" else os.mkfifo)
    _refused(_sessions(data), str(target), "a FIFO" if kind == "FIFO" else "a device")
    if name == "trials.parquet":
        with pytest.raises(UserError) as caught:
            load_dataset(data, "detection")
        assert str(target) in str(caught.value)


def test_a_session_folder_linked_to_another_is_named_not_counted_twice(data: Path) -> None:
    linked = data / "detection" / "sub-C1"
    linked.mkdir()
    (linked / "ses-1").symlink_to(data / "detection" / "sub-A1" / "ses-1", target_is_directory=True)
    _refused(_sessions(data), "sub-C1/ses-1", "sub-A1/ses-1", "link")
    with pytest.raises(UserError) as caught:
        load_dataset(data, "detection")
    assert "sub-A1" in str(caught.value) and "sub-C1" in str(caught.value) and "twice" in str(caught.value)


def test_a_trials_table_linked_into_another_session_is_refused(data: Path) -> None:
    target = data / "detection" / "sub-B1" / "ses-1" / "trials.parquet"
    _replace(target, lambda p: p.symlink_to(data / "detection" / "sub-A1" / "ses-1" / "trials.parquet"))
    _refused(_sessions(data), str(target), "link")
    with pytest.raises(UserError):
        load_dataset(data, "detection")


def test_an_oversized_session_json_is_refused(data: Path) -> None:
    target = data / "detection" / "sub-B1" / "ses-1" / "session.json"
    from psyop.session_json import MAX_SESSION_JSON_BYTES

    with open(target, "r+b") as handle:  # sparse: 1 MB of nothing over the limit
        handle.truncate(MAX_SESSION_JSON_BYTES + (1 << 20))
    _refused(_sessions(data), str(target), "byte limit")


def test_deleting_session_json_does_not_turn_a_real_session_simulated(data: Path, tmp_path: Path,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """A session recorded as real (here: labelled so) joins a simulated study; deleting its
    session.json (then its finalised tables too) leaves the log and the tables saying real."""
    from session_helpers import small_protocol

    from psyop.run.runner import SessionOptions

    assert _sessions(data).returncode == 0
    monkeypatch.setattr(SessionOptions, "simulated", property(lambda self: False))
    real = _run(small_protocol(tmp_path, "detection", 1), data, "R1")
    monkeypatch.undo()
    assert json.loads(real.metadata.read_text())["simulated"] is False
    real.metadata.unlink()
    write_dataset_description(data, simulated=True)
    assert json.loads((data / "dataset_description.json").read_text())["simulated"] is False
    # finalised files without session.json are refused by the checksum check (psyop.finalised) ...
    _refused(_sessions(data), str(real.directory), "without a session.json")
    with pytest.raises(UserError):
        load_dataset(data, "detection")
    # ... and without it, its finalised trials.parquet still says real
    unverified = subprocess.run([sys.executable, "-m", "psyop", "sessions", str(data), "--require-simulated"],
                                capture_output=True, text=True, timeout=120)
    _refused(unverified, "holds real sessions", "1 real")
    for table in (real.trials_parquet, real.frames_parquet, real.gaze_parquet):  # only the log is left
        table.unlink()
    _refused(_sessions(data), "mixed", "2 simulated, 1 real")
    write_dataset_description(data, simulated=True)
    assert json.loads((data / "dataset_description.json").read_text())["simulated"] is False


def test_a_fifo_among_the_log_segments_is_refused_by_recover(data: Path) -> None:
    paths = SessionPaths(data, "detection", "B1", 1)
    meta = json.loads(paths.metadata.read_text())
    paths.metadata.write_text(json.dumps({**meta, "status": "incomplete"}))
    fifo = paths.log_dir / "trials-007.psylog"
    os.mkfifo(fifo)
    done = subprocess.run([sys.executable, "-m", "psyop", "recover", str(data)], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert f"{fifo}: a log segment is not a regular file" in done.stderr
