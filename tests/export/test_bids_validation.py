"""A session with a ``gaze_validation:`` exports its validations as the BIDS eyetrack calibration fields
(issue 27 item 7; names, types and units as bids-validator-deno 3.0.2's schema) and still passes the
official validator."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from psyop.cli import main as cli_main
from psyop.export.gaze import display_from_metadata, gaze_on_image_px
from psyop.optics.angles import fick_direction

from tests.export.bids_validator import validate

REPO = Path(__file__).resolve().parents[2]


def test_validations_become_the_calibration_fields_and_the_export_validates(tmp_path: Path) -> None:
    text = (REPO / "protocols" / "ordinal.yaml").read_text().replace("repetitions: 15 ", "repetitions: 1 ")
    text = text.replace("name: ordinal", "name: ordval")
    protocols = tmp_path / "protocols"
    protocols.mkdir()
    (protocols / "ordval.yaml").write_text(text + "\ngaze_validation:\n  when: [start, end]\n")
    data, out = tmp_path / "data", tmp_path / "bids"
    assert cli_main(["simulate", "--data", str(data), "--protocols", str(protocols), "--participants", "1",
                     "--jobs", "1"]) == 0
    assert cli_main(["export", str(data), "--bids", str(out)]) == 0
    session = next(data.glob("ordval/sub-*/ses-1"))
    sub = session.parent.name
    validations = pd.read_parquet(session / "validation.parquet")
    overall = validations[validations["point"] == -1]
    meta = json.loads((session / "session.json").read_text())
    sidecar = json.loads((out / sub / "ses-1" / "beh" /
                          f"{sub}_ses-1_task-ordval_run-1_recording-eye1_physio.json").read_text())
    assert sidecar["CalibrationCount"] == 2 and sidecar["CalibrationType"] == "HV9"
    assert sidecar["AverageCalibrationError"] == pytest.approx(overall["mean_error_deg"].mean())
    assert sidecar["MaximalCalibrationError"] == pytest.approx(overall["max_error_deg"].max())
    assert sidecar["CalibrationUnit"] == "pixel"
    # the points on the eye's image, where the line from the eye's centre through the target meets it
    points = validations[validations["point"] >= 0].drop_duplicates("point").sort_values("point")
    target_m = fick_direction(points["target_az_deg"].to_numpy(), points["target_el_deg"].to_numpy())
    eye = sidecar["RecordedEye"]
    display = display_from_metadata(meta, "session.json")
    expected = gaze_on_image_px(target_m, display, eye, float(meta["rig"]["ipd_m"]))
    assert np.allclose(sidecar["CalibrationPosition"], expected)
    code, issues = validate(out)
    errors = {code: n for (severity, code), n in issues.items() if severity == "error"}
    assert code == 0 and not errors, f"validator exit {code}: {dict(issues)}"
