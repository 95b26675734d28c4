"""A simulated study run skips a session whose session.json (read as the typed record) says complete."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from psyop.errors import UserError
from psyop.run.simulate import SimulatedJob, run_job


def _write_meta(root: Path, text: str) -> None:
    ses = root / "study" / "sub-S01" / "ses-1"
    ses.mkdir(parents=True)
    (ses / "session.json").write_text(text)


def test_a_complete_session_is_not_run_again(tmp_path: Path) -> None:
    _write_meta(tmp_path, json.dumps({"status": "complete", "seed": 3}))
    job = SimulatedJob(tmp_path / "no_protocol_needed.yaml", "study", "S01", 3)
    assert run_job(job, tmp_path) == ("study", "S01", "already complete", 0)


def test_a_damaged_session_json_is_a_located_error(tmp_path: Path) -> None:
    _write_meta(tmp_path, "{not json")
    job = SimulatedJob(tmp_path / "no_protocol_needed.yaml", "study", "S01", 3)
    with pytest.raises(UserError, match="session.json is damaged"):
        run_job(job, tmp_path)
