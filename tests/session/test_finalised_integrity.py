"""Finalised files prove they are intact (psyop.finalised): session.json records each finalised
file's SHA-256; a flipped byte or a re-written value (valid parquet, different content) in any of
them is refused by load_dataset, `psyop sessions` and the analysis scripts before any figure uses
them; `psyop reseal --reason` is the recorded way to accept a deliberate edit."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from psyop.cli import main as cli_main
from psyop.errors import UserError
from psyop.finalised import FINALISED_KEY, RESEALS_KEY, sha256_file
from psyop.run.simulate import simulate_dataset
from psyop.statistics.dataset import load_dataset

from session_helpers import small_protocol

REPO = Path(__file__).resolve().parents[2]
FINALISED = ("trials.parquet", "frames.parquet")


@pytest.fixture(scope="module")
def pristine(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("finalised")
    protocol = small_protocol(root, "detection")
    simulate_dataset([protocol], root / "data", jobs=1, participants={"detection": 2})
    return root / "data"


@pytest.fixture()
def data(pristine: Path, tmp_path: Path) -> Path:
    copy = tmp_path / "data"
    shutil.copytree(pristine, copy)
    return copy


def _session(data: Path) -> Path:
    return data / "detection" / "sub-S01" / "ses-1"


def _flip_byte(path: Path) -> None:
    raw = bytearray(path.read_bytes())
    raw[len(raw) // 2] ^= 0x01
    path.write_bytes(bytes(raw))


def _rewrite_value(path: Path) -> None:
    """Change one value and write a valid parquet (what an edit in pandas does)."""
    table = pd.read_parquet(path)
    if "response" in table:
        table.loc[0, "response"] = "1" if table.loc[0, "response"] != "1" else "2"
    else:
        table.loc[0, "fixation_x_m"] = float(table.loc[0, "fixation_x_m"]) + 0.01
    table.to_parquet(path, index=False)
    pd.read_parquet(path)  # still a readable parquet file


def _run_cli(*argv: str) -> int:
    return cli_main(list(argv))


def test_finalisation_records_the_sha256_of_every_finalised_file(pristine: Path) -> None:
    meta = json.loads((_session(pristine) / "session.json").read_text())
    recorded = meta[FINALISED_KEY]
    present = sorted(p.name for p in _session(pristine).glob("*.parquet"))  # with a raw gaze stream: gaze.parquet too
    assert set(FINALISED) <= set(present) and sorted(recorded) == present
    for name in present:
        path = _session(pristine) / name
        assert recorded[name] == {"sha256": sha256_file(path), "size_bytes": path.stat().st_size}
    load_dataset(pristine, "detection")  # intact: loads
    assert _run_cli("sessions", str(pristine)) == 0


@pytest.mark.parametrize("name", FINALISED)
@pytest.mark.parametrize("damage", [_flip_byte, _rewrite_value], ids=["byte_flip", "rewritten_value"])
def test_damaged_or_edited_finalised_file_is_refused_before_any_figure(data: Path, name: str, damage, capsys) -> None:
    session = _session(data)
    damage(session / name)
    with pytest.raises(UserError) as caught:
        load_dataset(data, "detection")
    message = str(caught.value)
    assert str(session) in message and name in message and "\n" not in message
    capsys.readouterr()
    assert _run_cli("sessions", str(data)) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and name in err and str(session) in err
    # an analysis script (what `make figures` runs) refuses it too: one line, exit 2, no output
    out = data.parent / "fits.csv"
    result = subprocess.run([sys.executable, "analysis/fit_psychometric.py", "--study", "detection", "--data",
                             str(data), "--out", str(out)], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert result.returncode == 2, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and name in result.stderr
    assert not out.exists()


def test_reseal_records_a_deliberate_edit_with_reason_and_both_hashes(data: Path, capsys) -> None:
    session = _session(data)
    before = sha256_file(session / "trials.parquet")
    _rewrite_value(session / "trials.parquet")
    after = sha256_file(session / "trials.parquet")
    assert _run_cli("reseal", str(session), "--reason", "   ") == 2  # a blank reason is refused
    assert _run_cli("reseal", str(session), "--reason", "relabelled trial 0 after a protocol typo") == 0
    meta = json.loads((session / "session.json").read_text())
    [record] = meta[RESEALS_KEY]
    assert record["reason"] == "relabelled trial 0 after a protocol typo"
    assert record["files"] == {"trials.parquet": {"change": "changed", "old_sha256": before, "new_sha256": after}}
    assert meta[FINALISED_KEY]["trials.parquet"]["sha256"] == after
    load_dataset(data, "detection")
    capsys.readouterr()
    assert _run_cli("reseal", str(session), "--reason", "again") == 2  # nothing changed: nothing recorded
    assert len(json.loads((session / "session.json").read_text())[RESEALS_KEY]) == 1


def test_recover_rebuilds_a_deleted_damaged_file_from_the_log(data: Path, pristine: Path) -> None:
    session = _session(data)
    _flip_byte(session / "trials.parquet")
    assert _run_cli("recover", str(session)) == 2  # never overwrites a changed file on its own
    (session / "trials.parquet").unlink()  # what the refusal tells the user to do
    assert _run_cli("recover", str(session)) == 0
    assert json.loads((session / "session.json").read_text())[FINALISED_KEY]["trials.parquet"]["sha256"] == \
        sha256_file(session / "trials.parquet")
    pd.testing.assert_frame_equal(pd.read_parquet(session / "trials.parquet"),
                                  pd.read_parquet(_session(pristine) / "trials.parquet"))
    load_dataset(data, "detection")


def test_unrecorded_or_legacy_files_are_refused(data: Path) -> None:
    session = _session(data)
    shutil.copy(session / "frames.parquet", session / "extra.parquet")  # a finalised file nobody recorded
    with pytest.raises(UserError, match="extra.parquet has no SHA-256"):
        load_dataset(data, "detection")
    (session / "extra.parquet").unlink()
    meta = json.loads((session / "session.json").read_text())
    del meta[FINALISED_KEY]  # finalised by a psyop before checksums
    (session / "session.json").write_text(json.dumps(meta))
    with pytest.raises(UserError, match="reseal"):
        load_dataset(data, "detection")
    assert _run_cli("reseal", str(session), "--reason", "finalised before checksums") == 0  # on the record
    [record] = json.loads((session / "session.json").read_text())[RESEALS_KEY]
    assert {c["change"] for c in record["files"].values()} == {"unrecorded"}
    load_dataset(data, "detection")
    (session / "session.json").unlink()
    with pytest.raises(UserError, match="without a session.json"):
        load_dataset(data, "detection")
