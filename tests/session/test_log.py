"""The durable log: torn tails, segments, identity checks, parquet finalisation."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psyop.errors import UserError
from psyop.session.log.layout import SessionPaths, write_dataset_description
from psyop.session.log.schema import trial_schema
from psyop.session.log.store import SessionStore, recover_tables
from psyop.session.log.stream import DurableStreamWriter, read_stream_tolerant

SCHEMA = pa.schema([pa.field("trial", pa.int64()), pa.field("x", pa.float64())])


def _write(path: Path, n: int) -> None:
    with DurableStreamWriter(path, SCHEMA) as writer:
        for i in range(n):
            writer.append(pa.table({"trial": [i], "x": [i * 0.5]}))


@settings(max_examples=25)
@given(n=st.integers(1, 12), cut_fraction=st.floats(0.0, 1.0))
def test_truncated_stream_keeps_every_complete_batch(tmp_path_factory: pytest.TempPathFactory, n: int, cut_fraction: float) -> None:
    directory = tmp_path_factory.mktemp("torn")
    full = directory / "full.arrows"
    _write(full, n)
    data = full.read_bytes()
    # batch boundaries: the size of the stream after k batches (k = 0..n) without the end marker
    sizes = []
    for k in range(n + 1):
        p = directory / f"k{k}.arrows"
        writer = DurableStreamWriter(p, SCHEMA, fsync=False)
        for i in range(k):
            writer.append(pa.table({"trial": [i], "x": [i * 0.5]}))
        writer._file.flush()
        sizes.append(p.stat().st_size)
        writer.close()
    cut = int(cut_fraction * len(data))
    torn = directory / "torn.arrows"
    torn.write_bytes(data[:cut])
    table, _ = read_stream_tolerant(torn)
    complete = sum(1 for s in sizes[1:] if s <= cut)
    got = 0 if table is None else table.num_rows
    assert got == complete
    if table is not None:
        assert table.column("trial").to_pylist() == list(range(got))


def _schedule(n: int) -> pd.DataFrame:
    return pd.DataFrame({"trial": range(n), "block": 0, "condition": "c", "trial_seed": range(100, 100 + n)})


def test_resume_appends_a_new_segment_and_refuses_another_protocol(tmp_path: Path) -> None:
    paths = SessionPaths(tmp_path, "demo", "P1", 1)
    schedule = _schedule(5)
    meta = {"study": "demo", "participant": "P1", "session": 1, "seed": 1, "protocol_sha256": "abc", "n_trials_scheduled": 5}
    store = SessionStore(paths, trial_schema(schedule))
    assert store.open(meta) == set()
    for row in schedule.to_dict("records")[:2]:
        store.append_trial({**row, "response": "1", "correct": True}, None)
    store.close()  # as if killed after two trials (end marker or not does not matter)
    with pytest.raises(UserError, match="protocol_sha256 differs"):
        SessionStore(paths, trial_schema(schedule)).open({**meta, "protocol_sha256": "other"})
    store2 = SessionStore(paths, trial_schema(schedule))
    assert store2.open(meta) == {0, 1}
    assert store2.run_index == 1
    for row in schedule.to_dict("records")[2:]:
        store2.append_trial({**row, "response": "2", "correct": False}, None)
    trials, _ = store2.finalise(status="complete")
    assert trials["trial"].tolist() == [0, 1, 2, 3, 4]
    assert pd.read_parquet(paths.trials_parquet)["response"].tolist() == ["1", "1", "2", "2", "2"]
    assert json.loads(paths.metadata.read_text())["status"] == "complete"
    with pytest.raises(UserError, match="already complete"):
        SessionStore(paths, trial_schema(schedule)).open(meta)


def test_frames_of_an_unrecorded_trial_are_dropped(tmp_path: Path) -> None:
    from psyop.session.frames import FrameRecorder

    paths = SessionPaths(tmp_path, "demo", "P1", 1)
    schedule = _schedule(3)
    store = SessionStore(paths, trial_schema(schedule))
    store.open({"study": "demo", "seed": 1, "n_trials_scheduled": 3})
    frames = FrameRecorder()
    frames.add(trial=0, phase="interval1", frame=0, gaze_valid=True, gaze_held=False, image_checked=False)
    store.append_trial({**schedule.iloc[0].to_dict(), "response": "1"}, frames.table())
    orphan = FrameRecorder()
    orphan.add(trial=1, phase="interval1", frame=0, gaze_valid=True, gaze_held=False, image_checked=False)
    store._frames.append(orphan.table())  # killed between the frames and the trial record
    store.close()
    trials, frame_table = recover_tables(paths)
    assert trials["trial"].tolist() == [0]
    assert frame_table["trial"].tolist() == [0]


def test_dataset_description_is_simulated_only_if_every_session_is(tmp_path: Path) -> None:
    for participant, simulated in [("S1", True), ("S2", True)]:
        directory = tmp_path / "demo" / f"sub-{participant}" / "ses-1"
        directory.mkdir(parents=True)
        (directory / "session.json").write_text(json.dumps({"study": "demo", "simulated": simulated}))
    description = json.loads(write_dataset_description(tmp_path, simulated=True).read_text())
    assert description["simulated"] is True and description["n_sessions_simulated"] == 2
    real = tmp_path / "demo" / "sub-R1" / "ses-1"
    real.mkdir(parents=True)
    (real / "session.json").write_text(json.dumps({"study": "demo", "simulated": False}))
    description = json.loads(write_dataset_description(tmp_path, simulated=True).read_text())
    assert description["simulated"] is False and description["n_sessions_real"] == 1


def test_bad_identifiers_are_user_errors(tmp_path: Path) -> None:
    from psyop.session.log.layout import session_paths

    with pytest.raises(UserError, match="letters and digits"):
        session_paths(tmp_path, "demo", "P-1", 1)
    with pytest.raises(UserError, match="1 or more"):
        session_paths(tmp_path, "demo", "P1", 0)
