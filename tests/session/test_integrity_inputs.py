"""Every hostile input of issue 12 gives exit code 2 with a located message, never a traceback,
and leaves nothing behind that cannot be resumed."""

from __future__ import annotations

import errno
import json
import os
import re
from pathlib import Path

import pandas as pd
import pytest

import psyop.run.runner  # noqa: F401 - imported before capsys swaps sys.stderr (print_outcome's default)
from psyop.cli import main as cli_main
from psyop.protocol.design import count_conditions
from psyop.protocol.loader import MAX_PROTOCOL_BYTES
from psyop.session.log.layout import SessionPaths
from session_helpers import PROTOCOLS, small_protocol


def _protocol_with(tmp_path: Path, pattern: str, replacement: str, name: str = "p.yaml") -> Path:
    text, n = re.subn(pattern, replacement, (PROTOCOLS / "detection.yaml").read_text(), count=1, flags=re.M)
    assert n == 1
    path = tmp_path / name
    path.write_text(text)
    return path


def _fails_cleanly(capsys: pytest.CaptureFixture[str], argv: list[str], *expected: str) -> str:
    assert cli_main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "None" not in err, err
    for text in expected:
        assert text in err, err
    return err


@pytest.mark.parametrize("value, expected", [
    ("!!int abc", "as an integer"),
    ("!!float abc", "as a number"),
    ("!!bool maybe", "as true/false"),
    ("!!timestamp 2020-13-45", "as a date"),
    ("2020-02-30", "as a date"),
    ("1" * 5000, "5000 digits"),
])
def test_bad_yaml_values_are_located(tmp_path: Path, capsys: pytest.CaptureFixture[str], value: str, expected: str) -> None:
    path = _protocol_with(tmp_path, r"^(\s*repetitions:).*$", rf"\g<1> {value}")
    line = next(i for i, text in enumerate(path.read_text().splitlines(), 1) if "repetitions:" in text)
    err = _fails_cleanly(capsys, ["validate", str(path)], expected, f"{path}:{line}:")
    assert len(err) < 600  # a 5000-digit value is not echoed


def test_bound_messages_name_the_bound(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Messages said 'must be at most None'."""
    path = _protocol_with(tmp_path, r"^(\s*repetitions:).*$", r"\g<1> 2000000")
    _fails_cleanly(capsys, ["validate", str(path)], "at most 1000000")
    path = _protocol_with(tmp_path, r"^(\s*repetitions:).*$", r"\g<1> 0")
    _fails_cleanly(capsys, ["validate", str(path)], "at least 1")


def test_design_size_is_capped_before_expansion(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Two factors of 100000 levels reached 8 GB before the trial cap was checked."""
    stepped = "levels: {start: 0, step: 1, count: 100000}"
    path = _protocol_with(tmp_path, r"levels: \[1, 2, 3\]", stepped)
    text = re.sub(r"levels: \[0, 0.25, 0.5, 0.75, 1\]", stepped, path.read_text())
    path.write_text(text)
    _fails_cleanly(capsys, ["validate", str(path)], "over 100000 conditions")
    path = _protocol_with(tmp_path, r"levels: \[1, 2, 3\]", "levels: {start: 0, step: 1, count: 1000}")
    path.write_text(re.sub(r"(?m)^(\s*repetitions:).*$", r"\g<1> 1000", path.read_text()))
    _fails_cleanly(capsys, ["validate", str(path)], "5000 conditions x 1000 repetitions is over 1000000 trials")


def test_condition_count_matches_the_expansion_for_dependent_factors() -> None:
    from psyop.protocol.conditions import expand_conditions
    from psyop.protocol.design import Design

    design = Design.model_validate({
        "factors": {
            "mode": {"levels": ["a", "b", "c"]},
            "sep_D": {"depends_on": "mode", "levels_by": {"a": [1, 2], "b": [1], "c": {"start": 0, "step": 1, "count": 4}}},
            "x_D": {"depends_on": "sep_D", "levels_by": {1: [0.1, 0.2], 2: [0.3], 0: [1], 3: [1, 2, 3]}},
            "z_D": {"levels": [1, 2, 3, 4, 5]},
        },
        "repetitions": 2,
    })
    assert count_conditions(design.factors, 10**9) == len(expand_conditions(design))
    assert count_conditions(design.factors, 10) == 11  # stops early


def test_non_regular_and_oversized_protocol_files_are_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    fifo = tmp_path / "protocol.yaml"
    os.mkfifo(fifo)
    _fails_cleanly(capsys, ["validate", str(fifo)], "FIFO")  # used to block forever
    _fails_cleanly(capsys, ["validate", "/dev/zero"], "device")  # used to grow to 8 GB
    big = tmp_path / "big.yaml"
    big.write_text("# " + "x" * MAX_PROTOCOL_BYTES + "\n")
    _fails_cleanly(capsys, ["validate", str(big)], "byte limit")
    _fails_cleanly(capsys, ["run", str(fifo), "--participant", "P1", "--data", str(tmp_path / "d")], "FIFO")


@pytest.fixture(scope="module")
def protocol(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return small_protocol(tmp_path_factory.mktemp("inputs"), "detection", 1)


def _run(protocol: Path, data: Path, *extra: str, participant: str = "P1") -> list[str]:
    return ["run", str(protocol), "--participant", participant, "--data", str(data), "--no-progress",
            "--render", "cameras", *extra]


@pytest.mark.parametrize("participant", ["ab\n", "x" * 300, "a/b", "", "ab\x00"])
def test_participant_ids_are_matched_whole(protocol: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                           participant: str) -> None:
    _fails_cleanly(capsys, _run(protocol, tmp_path, participant=participant), "--participant", "letters and digits")
    assert not any(tmp_path.rglob("sub-*"))


def test_long_study_name_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _protocol_with(tmp_path, r"^  name: detection", "  name: " + "s" * 5000)
    # refused by protocol validation, located (issue 22: `psyop validate` accepted it), before any session
    err = _fails_cleanly(capsys, _run(path, tmp_path / "d"), "p.yaml:5:9", "study.name", "at most 64 characters")
    assert len(err) < 600 and not (tmp_path / "d").exists()


def test_huge_session_number_leaves_no_directory(protocol: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _fails_cleanly(capsys, _run(protocol, tmp_path, "--session", "9" * 26), "--session", "at most 9999")
    assert not any(tmp_path.rglob("ses-*"))


def test_data_root_that_is_a_file(protocol: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "a_file"
    target.write_text("not a directory")
    _fails_cleanly(capsys, _run(protocol, target), "not a directory", str(target))


@pytest.mark.parametrize("linked", ["study", "participant", "session", "log"])
def test_a_folder_linked_outside_the_data_root_is_refused(protocol: Path, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str], linked: str) -> None:
    """`data/detection/sub-L1 -> /elsewhere` was followed: `psyop run` wrote 8 files outside the root."""
    data, elsewhere = tmp_path / "data", tmp_path / "elsewhere"
    elsewhere.mkdir()
    study = next(line.split(":", 1)[1].strip() for line in protocol.read_text().splitlines()
                 if line.strip().startswith("name:"))
    parts = {"study": [study], "participant": [study, "sub-L1"], "session": [study, "sub-L1", "ses-1"],
             "log": [study, "sub-L1", "ses-1", "log"]}[linked]
    link = data.joinpath(*parts)
    link.parent.mkdir(parents=True, exist_ok=True)
    link.symlink_to(elsewhere, target_is_directory=True)
    _fails_cleanly(capsys, _run(protocol, data, participant="L1"), "outside the data root", str(link))
    assert list(elsewhere.iterdir()) == []
    inside = data / "inside"
    inside.mkdir()
    link.unlink()
    link.symlink_to(inside, target_is_directory=True)  # a link that stays inside the root is fine
    assert cli_main(_run(protocol, data, participant="L1")) == 0


def test_read_only_filesystem(protocol: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                              monkeypatch: pytest.MonkeyPatch) -> None:
    real_open = os.open

    def read_only_open(path, flags, *args, **kwargs):  # type: ignore[no-untyped-def]
        if str(path).startswith(str(tmp_path)) and flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT):
            raise OSError(errno.EROFS, "Read-only file system", str(path))
        return real_open(path, flags, *args, **kwargs)

    real_mkdir = Path.mkdir

    def read_only_mkdir(self, *args, **kwargs):  # type: ignore[no-untyped-def]
        if str(self).startswith(str(tmp_path)) and not self.exists():
            raise OSError(errno.EROFS, "Read-only file system", str(self))
        return real_mkdir(self, *args, **kwargs)

    monkeypatch.setattr(os, "open", read_only_open)
    monkeypatch.setattr(Path, "mkdir", read_only_mkdir)
    _fails_cleanly(capsys, _run(protocol, tmp_path / "data"), "Read-only file system")


def test_disk_full_stops_cleanly_and_the_session_resumes(protocol: Path, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str],
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    from psyop.session.log import stream

    data = tmp_path / "data"
    paths = SessionPaths(data, "detection", "P1", 1)
    real_write = os.write
    calls = {"n": 0}

    def full_after_a_while(fd: int, payload) -> int:  # type: ignore[no-untyped-def]
        calls["n"] += 1
        if calls["n"] > 12:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_write(fd, payload)

    monkeypatch.setattr(stream.os, "write", full_after_a_while)
    err = _fails_cleanly(capsys, _run(protocol, data), "No space left on device", "rerun the same command to resume")
    assert "safely in the log" in err
    monkeypatch.setattr(stream.os, "write", real_write)
    meta = json.loads(paths.metadata.read_text())
    assert meta["status"] == "incomplete" and "No space left" in meta["stopped"]
    assert cli_main(_run(protocol, data)) == 0
    final = pd.read_parquet(paths.trials_parquet)
    assert final["trial"].tolist() == list(range(15))


def test_live_response_device_on_the_virtual_clock_is_refused(protocol: Path, tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """Button presses 0.25 s apart were logged as 24-28 s response times."""
    _fails_cleanly(capsys, _run(protocol, tmp_path, "--responses", "serial:/dev/null", "--clock", "virtual"),
                   "--clock", "real time")
    assert not any(tmp_path.rglob("session.json"))


def test_resume_with_another_clock_is_refused(protocol: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """A virtual-clock session resumed with --clock real restarted trial_start_s at 0."""
    data = tmp_path / "data"
    paths = SessionPaths(data, "detection", "P1", 1)
    _interrupted_session(protocol, data, monkeypatch, "--clock", "virtual")
    capsys.readouterr()
    _fails_cleanly(capsys, _run(protocol, data, "--clock", "real"), "clock differs", "'virtual' there, 'real' now")
    runs = json.loads(paths.metadata.read_text())["runs"]
    assert runs[0]["clock"] == "virtual" and runs[0]["tracker"] == "sim" and runs[0]["responses"] == "sim"


@pytest.mark.parametrize("spec", ["--tracker=replay:{dir}/frames.parquet", "--tracker=replay:{dir}",
                                  "--pose=replay:{dir}", "--pose=replay-by-condition:{dir}"])
@pytest.mark.parametrize("bad", ["fifo", "oversize", "not_parquet"])
def test_replay_inputs_are_bounded_and_regular(protocol: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                               spec: str, bad: str) -> None:
    """A FIFO as frames.parquet blocked forever; a huge or non-parquet file gave a traceback."""
    from psyop.input_files import MAX_LOG_TABLE_BYTES

    source = tmp_path / "source"
    source.mkdir()
    frames = source / "frames.parquet"
    if bad == "fifo":
        os.mkfifo(frames)
        expected = "is a FIFO (named pipe)"
    elif bad == "oversize":
        with frames.open("wb") as handle:
            handle.truncate(MAX_LOG_TABLE_BYTES + 1)  # sparse: no disk used
        expected = f"over the {MAX_LOG_TABLE_BYTES} byte limit"
    else:
        frames.write_text("gaze,x\n1,2\n")
        expected = "not a parquet table"
    data = tmp_path / "data"
    _fails_cleanly(capsys, ["run", str(protocol), "--participant", "R1", "--data", str(data), "--no-progress",
                            spec.format(dir=source)], expected, str(frames))
    assert not list(data.rglob("trials-*"))  # nothing recorded


def test_replayed_session_json_must_be_a_regular_file(protocol: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    source = tmp_path / "source"
    source.mkdir()
    pd.DataFrame({"trial": [0]}).to_parquet(source / "frames.parquet")
    os.mkfifo(source / "session.json")
    _fails_cleanly(capsys, ["run", str(protocol), "--participant", "R1", "--data", str(tmp_path / "data"),
                            "--no-progress", f"--pose=replay:{source}"], "session.json is a FIFO")


def _interrupted_session(protocol: Path, data: Path, monkeypatch: pytest.MonkeyPatch, *options: str) -> None:
    """Run ``psyop run`` with ``options`` and stop it (Ctrl-C) after three durable trials."""
    from psyop.session.log import store

    original = store.SessionStore.append_trial

    def stop_after_three(self, row, frames, gaze=None):  # type: ignore[no-untyped-def]
        if int(row["trial"]) >= 3:
            raise KeyboardInterrupt
        original(self, row, frames, gaze)

    monkeypatch.setattr(store.SessionStore, "append_trial", stop_after_three)
    assert cli_main(_run(protocol, data, *options)) == 130
    monkeypatch.setattr(store.SessionStore, "append_trial", original)


def test_resume_with_a_protocol_edited_only_in_comments_needs_the_flag(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """--allow-protocol-change: comments may change (another hash); the session keeps its hash
    and trials, each run records its file's hash, and the result equals an uninterrupted run."""
    original = small_protocol(tmp_path, "detection")
    data = tmp_path / "data"
    _interrupted_session(original, data, monkeypatch)
    edited = tmp_path / "edited.yaml"
    edited.write_text("# fixed a typo in a comment\n" + original.read_text().replace("# assumed", "# an assumption"))
    capsys.readouterr()
    _fails_cleanly(capsys, _run(edited, data), "protocol_sha256 differs")
    assert cli_main([*_run(edited, data), "--allow-protocol-change"]) == 0
    paths = SessionPaths(data, "detection", "P1", 1)
    meta = json.loads(paths.metadata.read_text())
    first_sha = meta["runs"][0]["protocol_file_sha256"]
    assert meta["status"] == "complete" and meta["protocol_sha256"] == first_sha
    assert meta["runs"][-1]["protocol_file_sha256"] != first_sha
    assert cli_main(_run(original, tmp_path / "whole")) == 0
    whole = pd.read_parquet(SessionPaths(tmp_path / "whole", "detection", "P1", 1).trials_parquet)
    resumed = pd.read_parquet(paths.trials_parquet)
    from psyop.session.log.schema import TIMING_COLUMNS

    def stable(trials: pd.DataFrame) -> pd.DataFrame:
        return trials.drop(columns=[c for c in TIMING_COLUMNS if c in trials]).reset_index(drop=True)

    pd.testing.assert_frame_equal(stable(resumed), stable(whole))


@pytest.mark.parametrize("pattern, replacement, section", [
    (r"(?m)^(\s*duration_s:)\s*2\b", r"\g<1> 3", "trial"),  # same schedule, other stimulus timing
    (r"(?m)^(\s*repetitions:)\s*\d+", r"\g<1> 2", "design"),  # another schedule
    (r"(?m)^(\s*title:)\s*.*$", r"\g<1> Another title", "study"),
])
def test_allow_protocol_change_still_refuses_changed_values(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
        pattern: str, replacement: str, section: str) -> None:
    original = small_protocol(tmp_path, "detection")
    data = tmp_path / "data"
    _interrupted_session(original, data, monkeypatch)
    text, n = re.subn(pattern, replacement, original.read_text(), count=1)
    assert n == 1
    edited = tmp_path / "edited.yaml"
    edited.write_text(text)
    capsys.readouterr()
    _fails_cleanly(capsys, [*_run(edited, data), "--allow-protocol-change"], "values changed", f"'{section}'")


def test_recover_through_a_folder_linked_outside_the_data_root_is_refused(protocol: Path, tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """`psyop recover DATA/<study>/sub-L1/ses-1` with sub-L1 -> /elsewhere wrote trials.parquet there (recover
    builds its session paths from the folders it finds, not through session_paths' check)."""
    import shutil

    data, elsewhere = tmp_path / "data", tmp_path / "elsewhere"
    assert cli_main(_run(protocol, data, participant="L1")) == 0
    capsys.readouterr()
    participant = next(data.glob("*/sub-L1"))
    elsewhere.mkdir()
    shutil.move(str(participant), str(elsewhere / "sub-L1"))
    participant.symlink_to(elsewhere / "sub-L1", target_is_directory=True)
    (elsewhere / "sub-L1" / "ses-1" / "trials.parquet").unlink()
    before = sorted(p.name for p in (elsewhere / "sub-L1" / "ses-1").iterdir())
    err = _fails_cleanly(capsys, ["recover", str(participant / "ses-1")], "outside the data root", str(participant))
    assert err.count("\n") == 1
    assert sorted(p.name for p in (elsewhere / "sub-L1" / "ses-1").iterdir()) == before  # nothing written there
