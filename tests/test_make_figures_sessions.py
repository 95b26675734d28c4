"""`make figures` says which sessions it uses and refuses to pool simulated with real ones
(issue 13: a README demo run in data/ silently joined the simulated detection study)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from psyop.finalised import record_finalised

REPO = Path(__file__).resolve().parents[1]


def _session(data: Path, study: str, participant: str, *, simulated: bool) -> Path:
    directory = data / study / f"sub-{participant}" / "ses-1"
    directory.mkdir(parents=True)
    (directory / "trials.parquet").write_bytes(b"")
    meta = {"simulated": simulated, "status": "complete"}
    record_finalised(meta, directory, [directory / "trials.parquet"])
    (directory / "session.json").write_text(json.dumps(meta))
    return directory


def _make(target: str, data: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    # PY/STAMP point at this interpreter so the check never sets up a venv
    cmd = ["make", "--no-print-directory", "-C", str(REPO), target, f"DATA={data}", f"PY={sys.executable}",
           "STAMP=", *extra]
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300)


def test_figures_lists_sessions_per_study_and_refuses_a_mix(tmp_path: Path) -> None:
    data = tmp_path / "data"
    for p in ("S01", "S02"):
        _session(data, "detection", p, simulated=True)
    _session(data, "ordinal", "S01", simulated=True)
    ok = _make("figures-data", data)
    assert ok.returncode == 0, ok.stderr
    assert "detection: 2 sessions (2 simulated)" in ok.stdout and "ordinal: 1 sessions (1 simulated)" in ok.stdout

    _session(data, "detection", "sim01", simulated=False)  # e.g. a demo run written into data/
    refused = _make("figures-data", data)
    assert refused.returncode != 0
    assert "detection: 3 sessions (2 simulated, 1 real)" in refused.stdout + refused.stderr
    assert "mixed" in refused.stderr and "MIX=1" in refused.stderr
    pooled = _make("figures-data", data, "MIX=1")
    assert pooled.returncode == 0, pooled.stderr
    assert "MIXED" in pooled.stdout


def test_resimulate_never_deletes_real_sessions(tmp_path: Path) -> None:
    data = tmp_path / "data"
    _session(data, "detection", "S01", simulated=True)
    real = _session(data, "detection", "P01", simulated=False)
    result = _make("resimulate", data)
    assert result.returncode != 0 and "real sessions" in result.stderr and "nothing was deleted" in result.stderr
    assert (real / "session.json").exists() and (data / "detection" / "sub-S01").exists()


def test_figures_refuses_a_session_whose_finalised_file_changed(tmp_path: Path) -> None:
    data = tmp_path / "data"
    _session(data, "detection", "S01", simulated=True)
    edited = _session(data, "detection", "S02", simulated=True)
    (edited / "trials.parquet").write_bytes(b"\x00")  # damaged after finalisation
    refused = _make("figures-data", data)
    assert refused.returncode != 0
    assert f"{edited}: session refused: trials.parquet does not match the SHA-256" in refused.stderr
