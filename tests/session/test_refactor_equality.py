"""A simulated session of each shipped protocol records the same tables as before the session refactor
(issue 28, "Done when": the same trials.parquet, timing columns aside, checked by a test), on every CPU.

One participant (S01, ``psyop simulate``'s seed for base seed 2020) of each protocols/*.yaml is run headless
on the virtual clock exactly as ``psyop simulate`` runs it, and its tables are compared with the values
recorded from the tree before the refactor (26cd3cb; tests/session/recorded_sessions.py says how they were
recorded and why their provenance holds): integers, strings and booleans equal, floats within 1e-12.

- trials.parquet: every column but those added since on purpose (checked here to be what they should be).
- frames.parquet and gaze.parquet: every column (the virtual clock makes them deterministic), compared only
  where images were rendered and checked as when the values were recorded (``image_checked``/``image_ok``
  depend on whether an OpenGL context can be created).
- session.json: every field but the wall-clock and machine ones.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from psyop.datacontract import typed_response
from psyop.session.timing import TIMING_OK

from recorded_sessions import (
    ADDED_AFTER,
    ADDED_INTEGRITY,
    ADDED_LATENCY_TRIAL_COLUMNS,
    LATENCY_SUMMARY,
    ADDED_MODELS,
    ADDED_SESSION_KEYS,
    ROOT,
    STUDIES,
    differences,
    digests,
    golden_digests,
    measured_timing_columns,
    recorded_values,
    session_values,
    simulate,
)

pytestmark = pytest.mark.cross_cpu


def test_recorded_values_are_26cd3cbs() -> None:
    """The stored values hash to the digests 26cd3cb's sessions gave (stored data: the same on every CPU)."""
    golden = golden_digests()
    assert sorted(golden) == STUDIES
    for study in STUDIES:
        assert digests(recorded_values(study)) == golden[study], study


def _compared(got: dict, recorded: dict) -> tuple[str, ...]:
    """The parts compared (frames and gaze only where rendering was checked the same way)."""
    same_rendering = got["session_json"]["_rendering"] == recorded["session_json"]["_rendering"]
    return ("trials", "session_json") + (("frames", "gaze") if same_rendering else ())


@pytest.mark.parametrize("study", STUDIES)
def test_simulated_session_unchanged(tmp_path: Path, study: str) -> None:
    session = simulate(study, tmp_path)
    got, recorded = session_values(session, study), recorded_values(study)
    found = [d for part in _compared(got, recorded) for d in differences(got[part], recorded[part], part)]
    assert not found, f"{study}: {len(found)} differences from 26cd3cb's session, first: {found[:10]}"
    trials = pq.read_table(session / "trials.parquet").to_pylist()
    assert [{k: row[k] for k in ADDED_AFTER} for row in trials] == [
        typed_response(row["response"]) for row in trials], f"{study}: typed response columns"
    columns = measured_timing_columns(study)
    measured = [{k: row[k] for k in columns} for row in trials]
    assert all(v == 0 for row in measured for k, v in row.items() if k.endswith("_dropped_frames")), \
        f"{study}: the virtual clock dropped a frame"
    assert all(row[TIMING_OK] is None for row in measured), f"{study}: timing_ok without a timing: rule"
    meta = json.loads((session / "session.json").read_text())
    _check_added_latency(session, meta, trials)
    protocol = ROOT / "protocols" / f"{study}.yaml"
    assert meta["protocol_text"] == protocol.read_text()
    assert meta["protocol_file_sha256"] == hashlib.sha256(protocol.read_bytes()).hexdigest()


def _check_added_latency(session: Path, meta: dict, trials: list[dict]) -> None:
    """Issue 44's latency columns and blocks (recorded_sessions.ADDED_LATENCY_*): the trial columns are what the
    frames give, no latency was added, the intrinsic age is every valid frame's gaze age, session.json's
    summary.gaze_age is the frames' and its integrity names no late trial."""
    import math

    import numpy as np

    from psyop.session.latency import GazeLatency, frames_gaze_age, trials_gaze_age
    from psyop.session.timing import _recorded_phase

    frames = pq.read_table(session / "frames.parquet").to_pandas()
    phases = [_recorded_phase(p) for p in meta["phases"]]
    rule = GazeLatency.of_record(meta["gaze_latency"])
    assert (frames["added_latency_s"] == 0.0).all()
    valid = frames["gaze_valid"].to_numpy(dtype=bool)
    assert np.array_equal(frames["gaze_age_intrinsic_s"].to_numpy()[valid],
                          frames["gaze_age_at_display_s"].to_numpy()[valid])
    expected = trials_gaze_age(frames, phases, rule)
    for row in trials:
        want = expected.loc[row["trial"]].to_dict() if row["trial"] in expected.index \
            else dict.fromkeys(ADDED_LATENCY_TRIAL_COLUMNS)
        for column in ADDED_LATENCY_TRIAL_COLUMNS:
            got, value = row[column], want[column]
            value = None if value is None or (isinstance(value, float) and math.isnan(value)) else value
            assert got == value, (row["trial"], column, got, value)
        assert row["gaze_age_ok"] is None and row["gaze_age_over_share"] is None  # no bound in the shipped protocols
    assert any(row["gaze_age_median_s"] is not None for row in trials)
    summary = {k: v for k, v in meta["summary"][LATENCY_SUMMARY].items() if k != "scope"}
    assert not differences(summary, frames_gaze_age(frames, phases, rule), "gaze_age")
    assert {k: meta["integrity"][k] for k in ADDED_INTEGRITY} == ADDED_INTEGRITY


def test_a_changed_value_is_reported() -> None:
    """The check can fail: a float moved by 1e-10, a flipped response and a changed count are each reported,
    naming the table, column and row; a move of 1e-15 (another CPU's last bits) is not."""
    import pyarrow as pa

    recorded = recorded_values("detection")
    trials = recorded["trials"]
    assert isinstance(trials, pa.Table)
    rows = trials.to_pylist()
    level = next(k for k, v in rows[0].items() if isinstance(v, float) and v != 0.0)
    for change, expected in ((lambda r: r.update({level: r[level] * (1 + 1e-10)}), f"trials.{level}[3]"),
                             (lambda r: r.update(response="1" if r["response"] == "2" else "2"), "trials.response[3]"),
                             (lambda r: r.update(trial=r["trial"] + 1), "trials.trial[3]")):
        changed = [dict(r) for r in rows]
        change(changed[3])
        found = differences(pa.Table.from_pylist(changed, schema=trials.schema), trials, "trials")
        assert len(found) == 1 and found[0].startswith(expected + ":"), found
    nudged = [dict(r) for r in rows]
    nudged[3][level] = nudged[3][level] * (1 + 1e-15)
    assert differences(pa.Table.from_pylist(nudged, schema=trials.schema), trials, "trials") == []


def test_added_models_are_recorded(tmp_path: Path) -> None:
    """The session.json record of each model in ADDED_MODELS is the model's own (psyop.mesh's record of the file)."""
    from psyop.mesh.load import MeshFiles

    meta = json.loads((simulate("egocentric", tmp_path) / "session.json").read_text())
    recorded = {(m["file"], m["node"]): m for m in meta["meshes"]}
    for file, node in ADDED_MODELS:
        asset = MeshFiles(ROOT / "assets").load(file, node, base_dir=ROOT / "assets")
        assert recorded[(file, node)] == json.loads(json.dumps(asset.record()))


def test_added_session_keys_are_recorded(tmp_path: Path) -> None:
    meta = json.loads((simulate("detection", tmp_path) / "session.json").read_text())
    assert {k: meta[k] for k in ADDED_SESSION_KEYS} == ADDED_SESSION_KEYS
