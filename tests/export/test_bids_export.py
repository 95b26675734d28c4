"""`psyop export --bids`: simulated sessions of the five shipped studies exported as BIDS and checked
by the official validator (bids-validator-deno, the test extra); BEP020 eye tracking for every
session; gaze placed on each eye's image exactly as the renderer's camera maps pixels to rays."""

from __future__ import annotations

import gzip
import json
import shutil
from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from psyop.cli import main as cli_main
from psyop.errors import UserError
from psyop.export.bids import export_bids
from psyop.export.gaze import FRAME_LOG, RAW_GAZE_FILE, RAW_STREAM, gaze_on_image_px
from psyop.finalised import FINALISED_KEY, record_finalised
from psyop.optics.camera import make_eye_camera
from psyop.optics.display import DisplayProfile, VIVE_PRO

from tests.export.bids_validator import validate as _validate

REPO = Path(__file__).resolve().parents[2]
STUDIES = ("detection", "discrimination", "egocentric", "ordinal", "realism")


def _errors(issues: Counter) -> dict:
    return {code: n for (severity, code), n in issues.items() if severity == "error"}


@pytest.fixture(scope="module")
def simulated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    data = tmp_path_factory.mktemp("bids") / "data"
    assert cli_main(["simulate", "--data", str(data), "--protocols", str(REPO / "protocols"), "--participants", "2",
                     "--jobs", "1"]) == 0
    return data


@pytest.fixture(scope="module")
def exported(simulated: Path) -> Path:
    out = simulated.parent / "bids"
    assert cli_main(["export", str(simulated), "--bids", str(out)]) == 0
    return out


def test_export_of_the_five_simulated_studies_passes_the_bids_validator(exported: Path) -> None:
    code, issues = _validate(exported)
    assert code == 0 and not _errors(issues), f"validator exit {code}: {dict(issues)}"
    description = json.loads((exported / "dataset_description.json").read_text())
    assert description["Name"] and description["BIDSVersion"]
    participants = pd.read_csv(exported / "participants.tsv", sep="\t")
    assert participants["participant_id"].tolist() == ["sub-S01", "sub-S02"]
    assert (exported / "README.md").is_file()


def test_every_session_has_events_and_eyetrack_physio_per_eye(simulated: Path, exported: Path) -> None:
    for study in STUDIES:
        for session_json in sorted((simulated / study).glob("sub-*/ses-*/session.json")):
            meta = json.loads(session_json.read_text())
            sub, ses = session_json.parents[1].name, session_json.parent.name
            beh = exported / sub / ses / "beh"
            stem = f"{sub}_{ses}_task-{study}_run-1"
            trials = pd.read_parquet(session_json.parent / "trials.parquet")
            events = pd.read_csv(beh / f"{stem}_events.tsv", sep="\t", na_values="n/a", keep_default_na=False)
            assert list(events.columns[:3]) == ["onset", "duration", "trial_type"]
            assert {"response", "correct"} <= set(events.columns)
            assert len(events) == len(trials)
            assert events["trial_type"].tolist() == trials.sort_values("trial_start_s")["condition"].tolist()
            for index, eye in enumerate(meta["rig"]["eyes"]):
                recording = f"{stem}_recording-eye{index + 1}"
                sidecar = json.loads((beh / f"{recording}_physio.json").read_text())
                assert sidecar["PhysioType"] == "eyetrack" and sidecar["RecordedEye"] == eye
                assert sidecar["Columns"][:3] == ["timestamp", "x_coordinate", "y_coordinate"]
                assert sidecar["SampleCoordinateSystem"] == "gaze-on-screen"
                screen = sidecar["StimulusPresentation"]
                assert screen["ScreenResolution"] == [meta["display"]["width_px"], meta["display"]["height_px"]]
                assert len(screen["ScreenOrigin"]) == 2 and screen["ScreenDistance"] > 0
                assert len(screen["ScreenSize"]) == 2
                raw = session_json.parent / RAW_GAZE_FILE
                source = RAW_STREAM if raw.is_file() and len(pd.read_parquet(raw)) >= 2 else FRAME_LOG
                assert sidecar["GazeSource"] == source and source in sidecar["Description"]
                with gzip.open(beh / f"{recording}_physio.tsv.gz", "rt") as handle:
                    first = handle.readline().split("\t")
                float(first[0])  # headerless: the first line is a sample
                assert len(first) == len(sidecar["Columns"])
                assert (beh / f"{recording}_physioevents.tsv.gz").is_file()
            source = exported / "sourcedata" / study / sub / ses
            assert {"session.json", "protocol.yaml", "trials.parquet", "frames.parquet"} <= {p.name for p in source.iterdir()}


def test_the_validator_is_a_real_check_a_broken_export_fails(exported: Path, tmp_path: Path) -> None:
    """Negative control: the same export without the screen geometry the eye-tracking rules require."""
    broken = tmp_path / "broken"
    shutil.copytree(exported, broken)
    events_json = next(broken.glob("sub-S01/ses-1/beh/*task-detection_run-1_events.json"))
    sidecar = json.loads(events_json.read_text())
    del sidecar["StimulusPresentation"]
    events_json.write_text(json.dumps(sidecar))
    code, issues = _validate(broken)
    assert code != 0 and _errors(issues), dict(issues)


def test_the_raw_gaze_stream_is_preferred_when_the_session_has_one(simulated: Path, tmp_path: Path) -> None:
    data = tmp_path / "data"
    shutil.copytree(simulated / "detection" / "sub-S01", data / "detection" / "sub-S01")
    session = data / "detection" / "sub-S01" / "ses-1"
    t = np.arange(0.0, 30.0, 1 / 120)  # a 120 Hz tracker over the first trials
    pd.DataFrame({"run": 0, "trial": -1, "gaze_sample_t_s": t, "fixation_x_m": 0.0315, "fixation_y_m": 0.0, "fixation_z_m": -1.0,
                  "gaze_confidence": 0.9, "gaze_valid": True, "pupil_diameter_right_mm": 3.5}).to_parquet(
        session / RAW_GAZE_FILE, index=False)
    meta = json.loads((session / "session.json").read_text())
    record_finalised(meta, session, [session / RAW_GAZE_FILE])  # as finalisation records it
    (session / "session.json").write_text(json.dumps(meta))
    assert RAW_GAZE_FILE in meta[FINALISED_KEY]
    result = export_bids(data, tmp_path / "bids")
    assert [s.gaze_source for s in result.sessions] == [RAW_STREAM]
    beh = tmp_path / "bids" / "sub-S01" / "ses-1" / "beh"
    sidecar = json.loads((beh / "sub-S01_ses-1_task-detection_run-1_recording-eye1_physio.json").read_text())
    assert sidecar["GazeSource"] == RAW_STREAM and "pupil_size" in sidecar["Columns"]
    assert sidecar["SamplingFrequency"] == pytest.approx(120.0)  # measured from the samples, and said so
    assert "median interval" in sidecar["Description"]
    physio = pd.read_csv(beh / "sub-S01_ses-1_task-detection_run-1_recording-eye1_physio.tsv.gz", sep="\t",
                         header=None, names=sidecar["Columns"])
    assert len(physio) == len(t) and np.allclose(physio["x_coordinate"], 720.0) and np.allclose(physio["y_coordinate"], 800.0)
    assert (tmp_path / "bids" / "sourcedata" / "detection" / "sub-S01" / "ses-1" / RAW_GAZE_FILE).is_file()
    code, issues = _validate(tmp_path / "bids")
    assert code == 0 and not _errors(issues), dict(issues)


def test_export_refuses_a_damaged_session_and_a_non_empty_target(simulated: Path, tmp_path: Path) -> None:
    data = tmp_path / "data"
    shutil.copytree(simulated / "ordinal", data / "ordinal")
    target = data / "ordinal" / "sub-S02" / "ses-1" / "frames.parquet"
    raw = bytearray(target.read_bytes())
    raw[len(raw) // 3] ^= 0x40
    target.write_bytes(bytes(raw))
    with pytest.raises(UserError, match="sub-S02/ses-1.*frames.parquet does not match"):
        export_bids(data, tmp_path / "bids")
    assert not (tmp_path / "bids").exists()  # refused before anything was written
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("")
    shutil.rmtree(data / "ordinal" / "sub-S02")
    with pytest.raises(UserError, match="not empty"):
        export_bids(data, tmp_path / "full")


@pytest.mark.parametrize("eye", ["left", "right"])
@pytest.mark.parametrize("display", [
    VIVE_PRO, DisplayProfile("asym", 1000, 800, 90.0, -1.39, 1.25, -1.1, 1.3, 2.0),
    DisplayProfile("per_eye", 1000, 800, 90.0, -1.39, 1.25, -1.1, 1.3, left_tangents=(-1.2, 1.35, -1.0, 1.2))],
    ids=["vive_pro", "asymmetric_finite", "per_eye_fov"])
def test_gaze_lands_on_the_pixel_whose_ray_the_renderer_camera_casts(display: DisplayProfile, eye: str) -> None:
    """Inverse of psyop.optics.camera's conventional pixel_to_ray: a fixation point on the ray of
    pixel (x, y) from the eye's centre of rotation is placed at (x, y)."""
    ipd_m = 0.064
    rng = np.random.default_rng(1)
    uv = rng.uniform(0.0, 1.0, size=(50, 2))
    camera = make_eye_camera(display, eye, (0.0, 0.0, -1.0), ipd_m, 0.007, "conventional")
    rays = (camera.pixel_to_ray @ np.column_stack([uv, np.ones(len(uv))]).T).T
    distance = rng.uniform(0.3, 5.0, size=(len(uv), 1))
    points = camera.centre_of_projection_m + distance * rays / np.linalg.norm(rays, axis=1, keepdims=True)
    px = gaze_on_image_px(points, display, eye, ipd_m)
    np.testing.assert_allclose(px, uv * [display.width_px, display.height_px], atol=1e-6)
    assert np.isnan(gaze_on_image_px(np.array([[0.0, 0.0, 1.0]]), display, eye, ipd_m)).all()  # behind the eye


def test_an_interrupted_and_resumed_session_exports_one_bids_run_per_psyop_run(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import re

    from psyop.session.log import store

    text = re.sub(r"(?m)^(\s*repetitions:)\s*\d+", r"\g<1> 1", (REPO / "protocols" / "detection.yaml").read_text())
    protocol = tmp_path / "detection_small.yaml"
    protocol.write_text(text)
    data = tmp_path / "data"
    run = ["run", str(protocol), "--participant", "P1", "--data", str(data), "--no-progress", "--render", "cameras"]
    original = store.SessionStore.append_trial

    def stop_after_three(self, row, *rest):  # type: ignore[no-untyped-def]
        if int(row["trial"]) >= 3:
            raise KeyboardInterrupt
        original(self, row, *rest)

    monkeypatch.setattr(store.SessionStore, "append_trial", stop_after_three)
    assert cli_main(run) == 130
    monkeypatch.setattr(store.SessionStore, "append_trial", original)
    assert cli_main(run) == 0  # resumed: a second run
    trials = pd.read_parquet(data / "detection" / "sub-P1" / "ses-1" / "trials.parquet")
    assert sorted(trials["run"].unique()) == [0, 1]
    export_bids(data, tmp_path / "bids")
    beh = tmp_path / "bids" / "sub-P1" / "ses-1" / "beh"
    counts = [len(pd.read_csv(beh / f"sub-P1_ses-1_task-detection_run-{r}_events.tsv", sep="\t")) for r in (1, 2)]
    assert counts == [3, len(trials) - 3]
    assert (beh / "sub-P1_ses-1_task-detection_run-2_recording-eye1_physio.tsv.gz").is_file()
    code, issues = _validate(tmp_path / "bids")
    assert code == 0 and not _errors(issues), dict(issues)


def test_the_display_profile_is_read_back_as_session_json_records_it() -> None:
    from psyop.export.gaze import display_from_metadata
    from psyop.protocol import load_protocol
    from psyop.session.plan import compile_plan

    plan = compile_plan(load_protocol(REPO / "protocols" / "egocentric.yaml"))
    recorded = json.loads(json.dumps(plan.metadata(), default=str))  # as session.json holds it
    assert display_from_metadata(recorded, "session.json") == plan.display
    with pytest.raises(UserError, match="no display profile"):
        display_from_metadata({}, "session.json")


def test_eyetrack_sidecars_carry_the_measured_calibration_error(simulated: Path, exported: Path) -> None:
    """BIDS AverageCalibrationError / MaximalCalibrationError (degrees) and CalibrationCount: psyop.quality's
    error on the recalibration cross, before correction, over the run's trials (issue 27 item 5)."""
    from psyop.quality.session import measure_session

    for session_json in sorted((simulated / "detection").glob("sub-*/ses-*/session.json")):
        measures = measure_session(session_json.parent)[0]
        trials = pd.read_parquet(session_json.parent / "trials.parquet")
        sub, ses = session_json.parents[1].name, session_json.parent.name
        sidecar = json.loads((exported / sub / ses / "beh" /
                              f"{sub}_{ses}_task-detection_run-1_recording-eye1_physio.json").read_text())
        assert sidecar["CalibrationCount"] == len(trials)
        assert sidecar["AverageCalibrationError"] == pytest.approx(measures["accuracy_fixation_mean_deg"].mean())
        assert sidecar["MaximalCalibrationError"] == pytest.approx(measures["accuracy_fixation_max_deg"].max())
        assert 0 < sidecar["AverageCalibrationError"] <= sidecar["MaximalCalibrationError"] < 10
