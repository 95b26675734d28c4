"""session.json is parsed in one place (psyop.session_json) and read as one typed record
(psyop.session.log.record.read_record_file) by every reader: old records still read, and a damaged or
unreadable one is one line naming the file, exit code 2, from each command that reads it."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from psyop.errors import UserError
from psyop.session.log.record import SessionRecord, read_record_file, recorded_protocol_document
from psyop.session_json import MAX_SESSION_JSON_BYTES, read_session_json

RECORDED = sorted(Path(__file__).with_name("recorded").glob("*/session.json"))


@pytest.mark.parametrize("path", RECORDED, ids=[p.parent.name for p in RECORDED])
def test_recorded_session_json_reads_as_its_typed_record(path: Path) -> None:
    """Each recorded session.json (written before psyop recorded sim_tracker_faults or gaze_latency, with
    the response kinds' former spellings) gives typed fields equal to what the file holds."""
    raw = json.loads(path.read_text())
    record = read_record_file(path)
    assert record is not None and record.raw == raw
    assert (record.study, record.participant, record.session, record.simulated) == \
        (raw["study"], raw["participant"], raw["session"], raw["simulated"])
    assert record.response_kind == raw["response_kind"]
    assert record.response is not None and record.response.level_factor == raw["response"]["level_factor"]
    assert record.response.question == raw["response"]["question"]
    assert record.rig is not None and record.rig.eyes == tuple(raw["rig"]["eyes"])
    assert record.rig.ipd_m == raw["rig"]["ipd_m"]
    assert record.phases == raw["phases"] and record.phases
    assert record.gaze_latency is None and record.sim_tracker_faults is None  # not recorded then
    assert (record.seed, record.tracker, record.clock, record.status) == \
        (raw["seed"], raw["tracker"], raw["clock"], raw["status"])


def test_a_record_without_the_newer_fields_reads_with_none() -> None:
    record = SessionRecord.model_validate({"seed": 3, "participant": 7, "rig": {"eyes": [], "ipd_m": 0.06},
                                           "response": "two_interval", "phases": [1, {"name": "a"}],
                                           "simulated": "yes", "finalised_files": {"t.parquet": "x"}})
    assert record.participant == "7"  # an ID recorded as a number is its text
    assert record.rig is None and record.response is None and record.simulated is None
    assert record.phases == [{"name": "a"}] and record.finalised_files == {}
    assert recorded_protocol_document(record) == {}


def test_recorded_protocol_document_is_the_plain_yaml() -> None:
    record = SessionRecord(protocol_text="study: {name: x}\ndesign: {factors: {size_deg: {levels: [1]}}}\n")
    assert recorded_protocol_document(record)["design"] == {"factors": {"size_deg": {"levels": [1]}}}
    assert recorded_protocol_document(SessionRecord(protocol_text="- a list\n")) == {}
    assert recorded_protocol_document(SessionRecord(protocol_text="a: [unclosed\n")) == {}


@pytest.mark.parametrize(("content", "needle"), [
    (b'{"seed": 1,\n "status": }', "session.json is damaged (Expecting value)"),
    (b"[1, 2]", "session.json is not a JSON object"),
    (b'{"seed": "\xff"}', "session.json is damaged (not UTF-8 text"),
    (b'{"seed": "seven"}', "the recorded seed 'seven' is not an integer"),
])
def test_a_bad_record_is_a_user_error_naming_the_file(tmp_path: Path, content: bytes, needle: str) -> None:
    path = tmp_path / "session.json"
    path.write_bytes(content)
    with pytest.raises(UserError) as caught:
        read_record_file(path)
    text = str(caught.value)
    assert needle in text and str(path) in text and "\n" not in text, text
    if b"status" in content:
        assert f"{path}:2:12" in text  # the line and column of the JSON error


def test_absent_oversized_and_fifo_records(tmp_path: Path) -> None:
    path = tmp_path / "session.json"
    assert read_session_json(path) is None and read_record_file(path) is None
    with open(path, "wb") as handle:  # sparse
        handle.truncate(MAX_SESSION_JSON_BYTES + 1)
    with pytest.raises(UserError, match="byte limit"):
        read_record_file(path)
    path.unlink()
    os.mkfifo(path)
    with pytest.raises(UserError, match="not a regular file"):  # refused from stat: never opened, never blocks
        read_record_file(path)


def test_the_aliases_have_one_definition() -> None:
    import psyop.records as records
    import psyop.session.rows as rows

    for name in ("JsonObject", "JsonMapping", "TrialRow", "TrialRecord"):
        assert getattr(rows, name) is getattr(records, name)


@pytest.mark.parametrize("command", ["studies", "sessions", "export"])
def test_commands_that_read_session_json_refuse_a_damaged_one_in_one_line(tmp_path: Path, command: str,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """``psyop studies`` (statistics), ``psyop sessions`` (inventory) and ``psyop export`` (BIDS) read
    session.json through the one reader: a damaged file is one line naming it, exit code 2 (the command line's
    own entry point, in-process; tests/session/test_hostile_data.py runs it as a process)."""
    from psyop.cli import main

    session = tmp_path / "data" / "s" / "sub-P1" / "ses-1"
    session.mkdir(parents=True)
    (session / "session.json").write_text('{"study": "s",\n "seed": 1,,}')
    (session / "trials.parquet").write_bytes(b"")
    args = [command, str(tmp_path / "data")] + (["--bids", str(tmp_path / "bids")] if command == "export" else [])
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert f"{session / 'session.json'}:2:12" in err and "session.json is damaged" in err
