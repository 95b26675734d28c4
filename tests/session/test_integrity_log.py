"""Checksummed log segments: damage anywhere is detected, every intact record is kept,
what was lost is reported exactly, and resume re-runs only that.

Each case is checked against an uninterrupted run of the same protocol and seed.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import struct
import zlib
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import psyop.run.runner  # noqa: F401 - imported before capsys swaps sys.stderr (print_outcome's default)
from psyop.cli import main as cli_main
from psyop.session.log.layout import SessionPaths
from psyop.session.log.schema import TIMING_COLUMNS
from psyop.session.log.store import finalise_session, salvage
from psyop.session.log.stream import HEADER_BYTES, KIND_BATCH, KIND_END, KIND_SCHEMA, _parse_header, read_segment
from session_helpers import small_protocol

SEED = 7
N_TRIALS = 30


def _run_args(protocol: Path, data: Path, participant: str, seed: int | None = SEED) -> list[str]:
    return ["run", str(protocol), "--participant", participant, *(["--seed", str(seed)] if seed is not None else []),
            "--data", str(data), "--clock", "virtual", "--no-progress", "--render", "cameras"]


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(protocol, data root) of one uninterrupted session R1."""
    root = tmp_path_factory.mktemp("integrity_ref")
    protocol = small_protocol(root, "detection", 2)
    data = root / "data"
    assert cli_main(_run_args(protocol, data, "R1")) == 0
    return protocol, data


def _paths(data: Path) -> SessionPaths:
    return SessionPaths(data, "detection", "R1", 1)


def _copy(reference: tuple[Path, Path], tmp_path: Path) -> SessionPaths:
    """A crashed copy of the reference session: log only, status running."""
    _, data = reference
    target = tmp_path / "data"
    shutil.copytree(data, target)
    paths = _paths(target)
    paths.trials_parquet.unlink()
    paths.frames_parquet.unlink()
    meta = json.loads(paths.metadata.read_text())
    meta["status"] = "running"
    paths.metadata.write_text(json.dumps(meta))
    return paths


def _records(path: Path) -> list[tuple[int, int, int, int]]:
    """(offset, kind, key, total length) of every record of an intact segment."""
    data = path.read_bytes()
    out, pos = [], 0
    while pos < len(data):
        kind, key, length, _, _ = _parse_header(data, pos)  # type: ignore[misc]
        out.append((pos, kind, key, HEADER_BYTES + length))
        pos += HEADER_BYTES + length
    return out


def _flip(path: Path, offset: int) -> None:
    data = bytearray(path.read_bytes())
    data[offset] ^= 0x10
    path.write_bytes(bytes(data))


def _comparable(trials: pd.DataFrame) -> pd.DataFrame:
    return trials.drop(columns=[c for c in TIMING_COLUMNS if c in trials]).reset_index(drop=True)


def _reference_trials(reference: tuple[Path, Path]) -> pd.DataFrame:
    return pd.read_parquet(_paths(reference[1]).trials_parquet)


def test_segment_layout_is_two_schema_copies_batches_and_an_end_record(reference: tuple[Path, Path]) -> None:
    records = _records(_paths(reference[1]).trial_segment(0))
    kinds = [kind for _, kind, _, _ in records]
    assert kinds == [KIND_SCHEMA, KIND_SCHEMA, *[KIND_BATCH] * N_TRIALS, KIND_END]
    assert [key for _, kind, key, _ in records if kind == KIND_BATCH] == list(range(N_TRIALS))


def _regions(path: Path) -> list[tuple[str, int, int | None]]:
    """(region name, byte offset to flip, trial lost by that flip or None)."""
    regions: list[tuple[str, int, int | None]] = []
    for offset, kind, key, length in _records(path):
        name = {KIND_SCHEMA: "schema", KIND_BATCH: f"batch {key}", KIND_END: "footer"}[kind]
        lost = key if kind == KIND_BATCH else None
        regions.append((f"{name} header", offset + 9, lost))  # inside the key / kind field
        if length > HEADER_BYTES:
            regions.append((f"{name} payload", offset + HEADER_BYTES + (length - HEADER_BYTES) // 2, lost))
    return regions


def test_a_flipped_byte_in_every_region_loses_only_that_record(reference: tuple[Path, Path], tmp_path: Path) -> None:
    ref = _reference_trials(reference)
    segment = _paths(reference[1]).trial_segment(0)
    original = segment.read_bytes()
    paths = _copy(reference, tmp_path)
    for name, offset, lost in _regions(segment):
        paths.trial_segment(0).write_bytes(original)
        _flip(paths.trial_segment(0), offset)
        found = salvage(paths)
        expected = [t for t in range(N_TRIALS) if t != lost]
        assert found.trials is not None and found.trials["trial"].tolist() == expected, name
        assert found.report["damaged_records"], f"{name}: damage not reported"
        if lost is not None and lost < N_TRIALS - 1:
            assert found.report["lost_trials"] == [lost], name
        if lost is not None and "payload" in name:
            assert found.report["lost_trials"] == [lost], name  # the header names the trial
        kept = found.trials.set_index("trial")
        pd.testing.assert_frame_equal(_comparable(kept.reset_index()), _comparable(ref[ref["trial"].isin(expected)]),
                                      check_dtype=False)


def test_a_changed_response_value_is_detected(reference: tuple[Path, Path], tmp_path: Path) -> None:
    """The old log accepted a response changed from '2' to '1' with `correct` unchanged."""
    paths = _copy(reference, tmp_path)
    segment = paths.trial_segment(0)
    records = [r for r in _records(segment) if r[1] == KIND_BATCH]
    offset, _, key, length = records[10]
    data = bytearray(segment.read_bytes())
    body = data[offset + HEADER_BYTES: offset + length]
    ref = _reference_trials(reference)
    answer = ref.loc[ref["trial"] == key, "response"].item()
    other = b"1" if answer == "2" else b"2"
    # the response is a one-character string in the batch body: change the last occurrence of it
    position = bytes(body).rfind(answer.encode())
    assert position >= 0
    body[position:position + 1] = other
    data[offset + HEADER_BYTES: offset + length] = body
    segment.write_bytes(bytes(data))
    found = salvage(paths)
    assert key not in found.trials["trial"].tolist()
    assert found.report["lost_trials"] == [key]
    assert found.report["damaged_records"][0]["reason"] == "checksum"


def test_truncation_at_any_record_boundary_keeps_the_prefix(reference: tuple[Path, Path], tmp_path: Path) -> None:
    paths = _copy(reference, tmp_path)
    segment = _paths(reference[1]).trial_segment(0)
    original = segment.read_bytes()
    for offset, kind, key, length in _records(segment):
        for cut in (offset, offset + 5, offset + HEADER_BYTES + 3, offset + length - 1):
            paths.trial_segment(0).write_bytes(original[:cut])
            found = salvage(paths)
            got = [] if found.trials is None else found.trials["trial"].tolist()
            n_complete = sum(1 for o, k, _, ln in _records(segment) if k == KIND_BATCH and o + ln <= cut)
            assert got == list(range(n_complete)), cut
            assert found.report["lost_trials"] == [], "a torn tail is a crash, not damage"


@settings(max_examples=200, deadline=None)
@given(data=st.data())
def test_no_input_aborts_the_reader(reference: tuple[Path, Path], tmp_path_factory: pytest.TempPathFactory,
                                    data: st.DataObject) -> None:
    """Random flips, truncations and garbage: the reader returns, keeps the untouched records."""
    segment = _paths(reference[1]).trial_segment(0)
    original = bytearray(segment.read_bytes())
    damaged = bytearray(original)
    positions = data.draw(st.lists(st.integers(0, len(original) - 1), min_size=1, max_size=6))
    for position in positions:
        damaged[position] = data.draw(st.integers(0, 255))
    cut = data.draw(st.integers(0, len(original)))
    damaged = damaged[:cut] + data.draw(st.binary(max_size=64))
    path = tmp_path_factory.mktemp("fuzz") / "trials-000.psylog"
    path.write_bytes(bytes(damaged))
    read = read_segment(path)
    touched = set(positions) | set(range(cut, len(original)))
    for offset, kind, key, length in _records(segment):
        if kind == KIND_BATCH and not touched & set(range(offset, offset + length)) and read.schema is not None:
            assert key in read.keys


def test_damaged_frames_keep_the_trial_and_are_reported(reference: tuple[Path, Path], tmp_path: Path) -> None:
    paths = _copy(reference, tmp_path)
    records = [r for r in _records(paths.frame_segment(0)) if r[1] == KIND_BATCH]
    offset, _, key, length = records[0]
    _flip(paths.frame_segment(0), offset + HEADER_BYTES + 4)
    found = salvage(paths)
    assert found.trials["trial"].tolist() == list(range(N_TRIALS))
    assert found.report["frames_lost_for_trials"] == [key]
    assert key not in found.frames["trial"].tolist()


def test_recover_reports_and_records_the_loss_then_resume_reruns_only_it(
        reference: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    protocol, _ = reference
    paths = _copy(reference, tmp_path)
    batches = [r for r in _records(paths.trial_segment(0)) if r[1] == KIND_BATCH]
    offset, _, lost, length = batches[12]
    _flip(paths.trial_segment(0), offset + HEADER_BYTES + length // 3)
    assert cli_main(["recover", str(paths.directory)]) == 0
    out = capsys.readouterr().out
    assert f"{N_TRIALS - 1}/{N_TRIALS} trials" in out and "lost" in out and f"[{lost}]" in out
    meta = json.loads(paths.metadata.read_text())
    assert meta["status"] == "incomplete" and meta["integrity"]["lost_trials"] == [lost]
    assert cli_main(_run_args(protocol, paths.data_root, "R1")) == 0
    rerun = read_segment(paths.trial_segment(1))
    assert rerun.keys == [lost], "resume re-runs only the lost trial"
    final = pd.read_parquet(paths.trials_parquet)
    # the re-run trial's simulated drift depends on when it runs (tracker state), the rest does not
    pd.testing.assert_frame_equal(_comparable(final).drop(columns="drift_correction_deg"),
                                  _comparable(_reference_trials(reference)).drop(columns="drift_correction_deg"),
                                  check_dtype=False)
    meta = json.loads(paths.metadata.read_text())
    assert meta["status"] == "complete" and meta["integrity"]["lost_trials"] == []
    assert meta["integrity"]["damaged_records"][0]["trial"] == lost  # the damaged copy is still reported


def test_recover_leaves_a_complete_session_untouched(reference: tuple[Path, Path], tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    _, data = reference
    target = tmp_path / "data"
    shutil.copytree(data, target)
    paths = _paths(target)
    files = [paths.trials_parquet, paths.frames_parquet, paths.metadata]

    def state() -> list[tuple[int, int, str]]:
        return [(f.stat().st_ino, f.stat().st_mtime_ns, hashlib.sha256(f.read_bytes()).hexdigest()) for f in files]

    before = state()
    assert cli_main(["recover", str(target)]) == 0
    assert "untouched" in capsys.readouterr().out
    assert state() == before


def test_interrupted_finalisation_temp_files_are_cleaned_and_links_not_followed(
        reference: tuple[Path, Path], tmp_path: Path) -> None:
    paths = _copy(reference, tmp_path)
    stale = paths.directory / ".trials.parquet.99999999.tmp"
    stale.write_bytes(b"half a parquet file")
    victim = tmp_path / "victim.txt"
    victim.write_text("do not overwrite")
    planted = paths.directory / f".trials.parquet.{os.getpid()}.tmp"
    planted.symlink_to(victim)
    finalise_session(paths, status="complete")
    assert victim.read_text() == "do not overwrite"
    assert not stale.exists() and not os.path.lexists(planted)
    assert len(pd.read_parquet(paths.trials_parquet)) == N_TRIALS


def test_without_session_json_the_seed_in_the_log_decides(reference: tuple[Path, Path], tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """Before: a rerun with another seed kept the old seed's trials under the new seed."""
    protocol, _ = reference
    paths = _copy(reference, tmp_path)
    paths.metadata.unlink()
    assert cli_main(_run_args(protocol, paths.data_root, "R1", seed=8)) == 2
    assert "seed differs" in capsys.readouterr().err
    assert not paths.metadata.exists() or json.loads(paths.metadata.read_text()).get("seed") != 8
    assert cli_main(_run_args(protocol, paths.data_root, "R1", seed=None)) == 0  # the log's seed (7), not the default from the IDs
    final = pd.read_parquet(paths.trials_parquet)
    assert json.loads(paths.metadata.read_text())["seed"] == SEED
    pd.testing.assert_frame_equal(_comparable(final), _comparable(_reference_trials(reference)), check_dtype=False)


def test_recover_rebuilds_a_lost_session_json_from_the_log(reference: tuple[Path, Path], tmp_path: Path) -> None:
    paths = _copy(reference, tmp_path)
    paths.metadata.unlink()
    assert cli_main(["recover", str(paths.data_root)]) == 0
    meta = json.loads(paths.metadata.read_text())
    assert meta["seed"] == SEED and meta["rebuilt_from_log"]
    assert meta["n_trials_scheduled"] == N_TRIALS and meta["status"] == "complete"
    assert len(pd.read_parquet(paths.trials_parquet)) == N_TRIALS


def test_truncated_session_json_is_a_located_error(reference: tuple[Path, Path], tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    protocol, _ = reference
    paths = _copy(reference, tmp_path)
    text = paths.metadata.read_text()
    paths.metadata.write_text(text[: len(text) // 2])
    assert cli_main(_run_args(protocol, paths.data_root, "R1")) == 2
    assert cli_main(["recover", str(paths.directory)]) == 2
    err = capsys.readouterr().err
    assert "session.json is damaged" in err and "Traceback" not in err
    paths.metadata.unlink()
    os.mkfifo(paths.metadata)  # would block forever
    assert cli_main(["recover", str(paths.directory)]) == 2
    assert "not a regular file" in capsys.readouterr().err


def test_header_crc_covers_every_header_field() -> None:
    head = struct.Struct("<4sBBHqIII").pack(b"PSYR", 1, KIND_BATCH, 0, 3, 0, zlib.crc32(b""), 0)
    record = head + struct.pack("<I", zlib.crc32(head))
    assert _parse_header(record, 0) is not None
    for i in range(len(record)):
        damaged = bytearray(record)
        damaged[i] ^= 1
        assert _parse_header(bytes(damaged), 0) is None


def _old_reader_survives(path: Path) -> bool:
    """Read ``path`` as the pre-checksum recover did (batches -> pandas) in a forked child;
    False when the child was killed (pyarrow abort or crash) rather than returning."""
    import pyarrow as pa

    pid = os.fork()
    if pid == 0:  # pragma: no cover - child
        import faulthandler
        import resource

        faulthandler.disable()
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))  # an abort writes no core file
        os.dup2(os.open(os.devnull, os.O_WRONLY), 2)  # the abort message is expected
        try:
            with open(path, "rb") as handle:
                reader = pa.ipc.open_stream(handle)
                pa.Table.from_batches(list(reader), schema=reader.schema).to_pandas()
        except BaseException:  # noqa: BLE001 - an exception is survivable; only a kill is not
            pass
        os._exit(0)
    _, status = os.waitpid(pid, 0)
    return status == 0


def test_a_corrupt_legacy_ipc_segment_never_aborts_the_process(reference: tuple[Path, Path], tmp_path: Path) -> None:
    """Sessions recorded before checksums (plain Arrow IPC, `*.arrows`): a flipped byte made
    pyarrow abort the process (`Check failed`, exit 134) or crash. They are now read in a
    child process; what it read before failing is kept."""
    import pyarrow as pa

    from psyop.session.log.schema import trial_schema
    from psyop.session.log.stream import read_stream_tolerant

    trials = pd.read_parquet(_paths(reference[1]).trials_parquet).head(3)
    schema = trial_schema(trials[["trial", "block", "condition", "trial_seed"]])
    table = pa.Table.from_pandas(trials[schema.names], preserve_index=False).cast(schema)
    path = tmp_path / "trials-000.arrows"
    with open(path, "wb") as handle, pa.ipc.new_stream(handle, schema) as writer:
        ends = [handle.tell()]
        for batch in table.to_batches(max_chunksize=1):
            writer.write_batch(batch)
            ends.append(handle.tell())
    original = path.read_bytes()
    read, torn = read_stream_tolerant(path)
    assert read is not None and read.num_rows == 3 and not torn
    killers: list[int] = []
    for offset in range(ends[2] - 120, ends[2]):  # the tail of the second batch: its buffer offsets
        damaged = bytearray(original)
        damaged[offset] ^= 0xFF
        path.write_bytes(bytes(damaged))
        if not _old_reader_survives(path):
            killers.append(offset)
            if len(killers) == 3:  # the three checked below
                break
    assert killers, "no flip kills a direct pyarrow reader any more: the hazard guarded against is gone"
    for offset in killers[:3]:
        damaged = bytearray(original)
        damaged[offset] ^= 0xFF
        path.write_bytes(bytes(damaged))
        read, _ = read_stream_tolerant(path)  # returns: this process survives
        assert read is None or read.num_rows <= 3
