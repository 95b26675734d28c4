"""The raw gaze stream: every sample a gaze source delivered, durable beside the trial and frame
logs, finalised to gaze.parquet and read back by load_gaze."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest
from session_helpers import small_protocol

from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.devices.gaze.pupil import pupil_eyes
from psyop.session.gaze.sample import EyeSample, RawGazeSample, direction_to_angles_deg
from psyop.session.log.layout import session_paths
from psyop.session.log.raw_gaze import raw_gaze_table
from psyop.session.log.schema import GAZE_SCHEMA
from psyop.session.log.stream import read_segment
from psyop.session.loop import TrialLoop
from psyop.run.runner import SessionOptions, run_session
from psyop.statistics.dataset import load_gaze


def _options(data: Path, **kw: object) -> SessionOptions:
    return SessionOptions(participant="P1", seed=5, data_root=data, progress=False, render="cameras",
                          every_frame=True, **kw)  # type: ignore[arg-type]


def test_every_sample_the_frames_used_is_in_the_raw_stream_with_its_run_and_trial(tmp_path: Path) -> None:
    protocol = load_protocol(small_protocol(tmp_path, "detection", repetitions=1))
    data = tmp_path / "data"
    outcome = run_session(protocol, compile_schedule, _options(data))
    assert outcome.status == "complete"
    paths = session_paths(data, protocol.study.name, "P1", 1)
    gaze = pd.read_parquet(paths.gaze_parquet)
    assert list(gaze.columns) == GAZE_SCHEMA.names
    frames = pd.read_parquet(paths.frames_parquet)
    trials = pd.read_parquet(paths.trials_parquet)
    used = frames.loc[~frames["gaze_held"], "gaze_sample_t_s"].unique()
    assert len(used) > 100
    assert set(used) <= set(gaze["gaze_sample_t_s"]), "a sample a frame used is missing from the raw stream"
    # delivered once each, oldest first; each tagged with the trial in progress when it was delivered
    assert gaze["gaze_sample_t_s"].is_monotonic_increasing and gaze["gaze_sample_t_s"].is_unique
    assert set(gaze["run"]) == {0}
    for row in trials.itertuples():
        mine = gaze[gaze["trial"] == row.trial]
        assert len(mine), row.trial
        assert (mine["received_s"] <= row.trial_end_s + 1e-9).all()
    # raw means uncorrected: a frame's fixation is its raw sample rotated by the trial's drift correction
    merged = frames[frames["gaze_valid"]].merge(gaze, on="gaze_sample_t_s", suffixes=("", "_raw"))
    first_phase = frames["phase"].iloc[0]  # still under the previous trial's correction
    merged = merged[merged["phase"] != first_phase].merge(trials[["trial", "drift_correction_deg"]], on="trial")
    assert len(merged) > 100
    for trial, part in merged.groupby("trial"):
        used = np.array([direction_to_angles_deg(np.array(v)) for v in
                         part[["fixation_x_m", "fixation_y_m", "fixation_z_m"]].to_numpy()])
        raw = np.array([direction_to_angles_deg(np.array(v)) for v in
                        part[["fixation_x_m_raw", "fixation_y_m_raw", "fixation_z_m_raw"]].to_numpy()])
        offset = used - raw
        assert np.ptp(offset, axis=0) == pytest.approx([0.0, 0.0], abs=1e-9), trial
        assert math.hypot(*offset[0]) == pytest.approx(part["drift_correction_deg"].iloc[0], abs=1e-9)
    loaded = load_gaze(data, protocol.study.name)
    assert len(loaded) == len(gaze) and set(loaded["participant"]) == {"P1"} and set(loaded["session"]) == {1}
    assert loaded.attrs["n_sessions_without_gaze"] == 0


def test_samples_of_an_interrupted_trial_are_kept_and_a_resume_adds_its_own_run(tmp_path: Path,
                                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    protocol = load_protocol(small_protocol(tmp_path, "detection", repetitions=1))
    data = tmp_path / "data"
    original = TrialLoop._await_response

    def interrupt_trial_3(self: TrialLoop, row, frames):  # type: ignore[no-untyped-def]
        if int(row["trial"]) == 3:
            raise KeyboardInterrupt
        return original(self, row, frames)

    monkeypatch.setattr(TrialLoop, "_await_response", interrupt_trial_3)
    assert run_session(protocol, compile_schedule, _options(data)).status == "interrupted"
    monkeypatch.setattr(TrialLoop, "_await_response", original)
    paths = session_paths(data, protocol.study.name, "P1", 1)
    # durable in the run's segment: trials 0-2 with their records, trial 3's samples after it stopped
    segment = read_segment(paths.gaze_segment(0))
    assert segment.keys == [0, 1, 2, 3] and segment.clean_end and not segment.damage
    first = segment.table.to_pandas()
    assert (first["trial"] == 3).sum() > 0
    assert run_session(protocol, compile_schedule, _options(data)).status == "complete"
    gaze = pd.read_parquet(paths.gaze_parquet)
    assert set(gaze["run"]) == {0, 1}
    assert ((gaze["run"] == 0) & (gaze["trial"] == 3)).sum() == (first["trial"] == 3).sum()  # the discarded trial's
    assert ((gaze["run"] == 1) & (gaze["trial"] == 3)).sum() > 0  # and its re-run
    pd.testing.assert_frame_equal(gaze[gaze["run"] == 0].reset_index(drop=True), first)
    meta = json.loads(paths.metadata.read_text())
    assert meta["integrity"]["damaged_records"] == []


def test_raw_table_keeps_both_eyes_and_every_field() -> None:
    left = EyeSample((-0.03, 0.0, 0.0), (0.0, 0.0, -1.0), 3.5, 40.0)
    sample = RawGazeSample(1234.5, 1.25, 1.26, True, 0.97, (0.1, 0.2, -0.9), (0.4, 0.6), left, None)
    row = raw_gaze_table([sample], run=2, trial=7).to_pylist()[0]
    assert row["run"] == 2 and row["trial"] == 7 and row["tracker_t_s"] == 1234.5 and row["gaze_sample_t_s"] == 1.25
    assert row["eye_centre_left_x_m"] == -0.03 and row["pupil_diameter_left_mm"] == 3.5
    assert row["pupil_diameter_left_px"] == 40.0 and (row["norm_pos_x"], row["norm_pos_y"]) == (0.4, 0.6)
    assert math.isnan(row["pupil_diameter_right_mm"]) and math.isnan(row["eye_centre_right_z_m"])
    assert raw_gaze_table([], run=0, trial=0).schema.equals(GAZE_SCHEMA)
    assert isinstance(raw_gaze_table([sample], run=0, trial=0), pa.Table)


def test_pupil_binocular_datum_maps_eye_1_to_the_left_eye() -> None:
    # the layout of a Pupil Capture 'gaze.3d.01.' datum (docs.pupil-labs.com, Network API, gaze datum format)
    payload = {"topic": "gaze.3d.01.", "eye_centers_3d": {0: [30.0, 10.0, -20.0], 1: [-30.0, 10.0, -20.0]},
               "gaze_normals_3d": {0: [0.0, 0.0, 1.0], 1: [0.1, 0.0, 0.995]},
               "base_data": [{"id": 0, "diameter": 41.0, "diameter_3d": 3.1},
                             {"id": 1, "diameter": 43.0, "diameter_3d": 3.3}]}
    left, right = pupil_eyes(payload)
    assert left is not None and right is not None
    assert left.centre_m == pytest.approx((-0.03, -0.01, 0.02)) and left.pupil_diameter_mm == 3.3
    assert right.centre_m == pytest.approx((0.03, -0.01, 0.02)) and right.pupil_diameter_px == 41.0
    assert left.normal == pytest.approx((0.1, 0.0, -0.995))  # world camera z forward -> head -z forward
    mono = pupil_eyes({"topic": "gaze.3d.1.", "eye_center_3d": [1.0, 2.0, 3.0], "gaze_normal_3d": [0.0, 0.0, 1.0]})
    assert mono[1] is None and mono[0] is not None and mono[0].centre_m == pytest.approx((0.001, -0.002, -0.003))
