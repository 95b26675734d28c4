"""Disk full and I/O errors: every write is atomic, every error is one line with exit 2, and the
next ordinary command (`psyop run` again, `psyop recover`) heals the state with no trial lost.

Faults are injected two ways: the real kernel (a file-size limit, RLIMIT_FSIZE, in a child
process makes a write fail with EFBIG exactly as a full disk fails with ENOSPC), and
``os.fsync``/``os.write`` raising ENOSPC or EIO while one chosen psyop function runs (the
session's writes of session.json, the segments' end records, the adaptive stop record, the
dataset description).
"""

from __future__ import annotations

import contextlib
import errno
import os
import resource
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pandas as pd
import pytest

from psyop.atomic import fsync_dir, io_error, stale_temp_files, write_atomic
from psyop.cli import main as cli_main
from psyop.session.log.layout import SessionPaths
from psyop.session.log.schema import TIMING_COLUMNS

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "adaptive"))
from test_adaptive_session import adaptive_detection

SEED = 7


def _argv(protocol: Path, data: Path, participant: str) -> list[str]:
    return ["run", str(protocol), "--participant", participant, "--seed", str(SEED), "--data", str(data),
            "--clock", "virtual", "--no-progress", "--render", "cameras"]


def _comparable(trials: pd.DataFrame) -> pd.DataFrame:
    return trials.drop(columns=[c for c in TIMING_COLUMNS if c in trials]).reset_index(drop=True)


@contextlib.contextmanager
def _disk_fails(monkeypatch: pytest.MonkeyPatch, code: int, calls: tuple[str, ...] = ("fsync", "fdatasync", "write")
                ) -> Iterator[None]:
    """While active, the named ``os`` calls raise OSError(code) (a full disk, a failing disk)."""
    def fail(*args: object, **kwargs: object) -> None:
        raise OSError(code, os.strerror(code))

    with monkeypatch.context() as patch:
        for name in calls:
            patch.setattr(os, name, fail)
        yield


def _fail_during(monkeypatch: pytest.MonkeyPatch, owner: object, name: str, code: int, *, skip: int = 0,
                 calls: tuple[str, ...] = ("fsync", "fdatasync", "write")) -> list[int]:
    """Make ``owner.name`` run with a failing disk (after ``skip`` clean calls); the calls made."""
    original = getattr(owner, name)
    seen: list[int] = []

    def wrapped(*args: object, **kwargs: object) -> object:
        seen.append(1)
        if len(seen) <= skip:
            return original(*args, **kwargs)
        with _disk_fails(monkeypatch, code, calls):
            return original(*args, **kwargs)

    monkeypatch.setattr(owner, name, wrapped)
    return seen


def _one_line_error(capsys: pytest.CaptureFixture[str], *needles: str) -> str:
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if "error:" in line]
    assert len(lines) == 1, err
    assert "Traceback" not in err, err
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


# -- the helper ---------------------------------------------------------------------------------
@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EIO])
@pytest.mark.parametrize("call", ["fsync", "replace"])
def test_write_atomic_leaves_the_old_file_and_no_temp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                      code: int, call: str) -> None:
    target = tmp_path / "results" / "a.csv"
    write_atomic(target, "old\n")
    with _disk_fails(monkeypatch, code, (call,)), pytest.raises(OSError) as caught:
        write_atomic(target, lambda handle: (handle.write(b"new " * 10_000), handle.flush()))
    assert caught.value.errno == code and caught.value.filename == str(target)
    assert target.read_text() == "old\n"
    assert stale_temp_files(target.parent) == []
    message = str(io_error(caught.value))
    assert str(target) in message and os.strerror(code) in message and "\n" not in message


def test_directory_fsync_errors_are_errors(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with _disk_fails(monkeypatch, errno.EIO, ("fsync",)), pytest.raises(OSError) as caught:
        fsync_dir(tmp_path)
    assert caught.value.errno == errno.EIO and caught.value.filename == str(tmp_path)
    with _disk_fails(monkeypatch, errno.EINVAL, ("fsync",)):
        fsync_dir(tmp_path)  # this file system cannot sync folders: nothing to make durable


def _efbig_child(limit_bytes: int) -> None:
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # the write fails with EFBIG instead of killing the process
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))


def test_a_real_file_size_limit_fails_the_write_cleanly(tmp_path: Path) -> None:
    """The kernel refuses a write past RLIMIT_FSIZE (EFBIG): the old file stays whole, one line, exit 2."""
    target = tmp_path / "schema.json"
    write_atomic(target, "{}\n")
    done = subprocess.run([sys.executable, "-m", "psyop", "schema", "--out", str(target)], capture_output=True,
                          text=True, preexec_fn=lambda: _efbig_child(1000), timeout=120)
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr
    assert str(target) in done.stderr and "File too large" in done.stderr
    assert target.read_text() == "{}\n" and stale_temp_files(tmp_path) == []


# -- a session under a real file-size limit -----------------------------------------------------
@pytest.mark.parametrize("limit_bytes", [4_000, 20_000])
def test_session_under_a_file_size_limit_heals_by_rerunning(tmp_path: Path, detection_small: Path,
                                                            limit_bytes: int) -> None:
    """Each limit stops the session at another write (session.json at open; a segment mid-session);
    one line, exit 2; rerunning the same command then gives the trials of an uninterrupted run."""
    reference = tmp_path / "reference"
    assert cli_main(_argv(detection_small, reference, "F1")) == 0
    data = tmp_path / "data"
    done = subprocess.run([sys.executable, "-m", "psyop", *_argv(detection_small, data, "F1")],
                          capture_output=True, text=True, preexec_fn=lambda: _efbig_child(limit_bytes), timeout=300)
    assert done.returncode == 2, done.stderr
    errors = [line for line in done.stderr.splitlines() if "error:" in line]
    assert len(errors) == 1 and "Traceback" not in done.stderr, done.stderr
    assert "File too large" in errors[0] and "rerun" in errors[0]
    assert cli_main(_argv(detection_small, data, "F1")) == 0
    paths = SessionPaths(data, "detection", "F1", 1)
    final = pd.read_parquet(paths.trials_parquet)
    expected = pd.read_parquet(SessionPaths(reference, "detection", "F1", 1).trials_parquet)
    pd.testing.assert_frame_equal(_comparable(final), _comparable(expected), check_dtype=False)


# -- each write of a session, failing -----------------------------------------------------------
@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EIO])
@pytest.mark.parametrize("site", ["log folder fsync", "rendering metadata", "segment end record",
                                  "session.json in finalise", "finalised parquet"])
def test_each_session_write_fails_in_one_line_and_heals(tmp_path: Path, detection_small: Path,
                                                        monkeypatch: pytest.MonkeyPatch,
                                                        capsys: pytest.CaptureFixture[str], site: str, code: int) -> None:
    from psyop.session.log import store

    reference = tmp_path / "reference"
    assert cli_main(_argv(detection_small, reference, "W1")) == 0
    expected = pd.read_parquet(SessionPaths(reference, "detection", "W1", 1).trials_parquet)
    capsys.readouterr()
    data = tmp_path / "data"
    if site == "log folder fsync":  # the new segment's name made durable: its error is an error
        from psyop.session.log import stream

        _fail_during(monkeypatch, stream, "fsync_dir", code, calls=("fsync",))
    elif site == "rendering metadata":  # store.update_metadata(rendering=...) just after open
        _fail_during(monkeypatch, store.SessionStore, "update_metadata", code)
    elif site == "segment end record":
        _fail_during(monkeypatch, store.DurableStreamWriter, "close", code)
    elif site == "session.json in finalise":
        _fail_during(monkeypatch, store.SessionStore, "finalise", code, calls=("fsync",))  # segments: fdatasync
    else:
        _fail_during(monkeypatch, store, "_write_parquet_atomic", code)
    assert cli_main(_argv(detection_small, data, "W1")) == 2
    line = _one_line_error(capsys, os.strerror(code))
    assert ("psyop recover" in line) or ("rerun the same command" in line), line
    monkeypatch.undo()
    paths = SessionPaths(data, "detection", "W1", 1)
    if site in ("log folder fsync", "rendering metadata"):  # nothing ran yet: rerunning runs the session
        assert cli_main(_argv(detection_small, data, "W1")) == 0
    else:  # every trial was recorded: recover finishes the session in one step
        assert cli_main(["recover", str(data)]) == 0
    final = pd.read_parquet(paths.trials_parquet)
    pd.testing.assert_frame_equal(_comparable(final), _comparable(expected), check_dtype=False)
    assert stale_temp_files(paths.directory) == []


def test_dataset_description_after_a_complete_session(tmp_path: Path, detection_small: Path,
                                                      monkeypatch: pytest.MonkeyPatch,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    from psyop.run import runner

    data = tmp_path / "data"
    _fail_during(monkeypatch, runner, "write_dataset_description", errno.ENOSPC)
    assert cli_main(_argv(detection_small, data, "D1")) == 2
    line = _one_line_error(capsys, "dataset_description.json", "psyop recover")
    assert "finalised" in line
    monkeypatch.undo()
    assert not (data / "dataset_description.json").exists()
    assert cli_main(["recover", str(data)]) == 0
    import json

    assert json.loads((data / "dataset_description.json").read_text())["simulated"] is True
    assert len(pd.read_parquet(SessionPaths(data, "detection", "D1", 1).trials_parquet)) == 15


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EIO])
def test_adaptive_stop_record_fails_in_one_line_and_resumes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                            capsys: pytest.CaptureFixture[str], code: int) -> None:
    from psyop.session import loop

    protocol = adaptive_detection(tmp_path, "{procedure: quest_plus, start: 0.5, min: 0, max: 1.5, grid_points: 51, "
                                  "target_sd: 0.2}", 12, backs="[1, 3]")
    reference = tmp_path / "reference"
    assert cli_main(_argv(protocol, reference, "A1")) == 0
    expected = pd.read_parquet(SessionPaths(reference, "detection", "A1", 1).trials_parquet)
    capsys.readouterr()
    data = tmp_path / "data"
    seen = _fail_during(monkeypatch, loop.TrialLoop, "_record_stops", code, skip=1)  # the first is at the start
    status = cli_main(_argv(protocol, data, "A1"))
    assert len(seen) >= 2, "the stop rule never fired: make target_sd reachable"
    assert status == 2
    _one_line_error(capsys, "session.json", os.strerror(code), "rerun the same command")
    monkeypatch.undo()
    assert cli_main(_argv(protocol, data, "A1")) == 0
    final = pd.read_parquet(SessionPaths(data, "detection", "A1", 1).trials_parquet)
    compared = ["trial", "condition", "level_D", "correct", "response"]
    pd.testing.assert_frame_equal(final[compared].reset_index(drop=True), expected[compared].reset_index(drop=True),
                                  check_dtype=False)
