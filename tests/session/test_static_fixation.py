"""A static fixation target (a ``fixation_target`` without ``path``) is fixated by the simulated observer in
every phase that shows the scene, where each trial draws it (factor levels of its centre included), and
psyop.quality measures accuracy and precision against it. Before, such phases were free viewing: the
simulated gaze wandered over 10 deg while the participant was shown a target to look at, and the quality
table had no accuracy or precision for them. A scene without a fixation target still views freely."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from psyop.cli import main as cli_main
from psyop.optics.angles import fick_angles_deg
from psyop.quality.session import measure_session

PROTOCOL = """\
psyop_protocol: 1
study: {name: fixdot, title: static fixation target}
display: {profile: vive_pro, eye_model: gullstrand_emsley_relaxed, ipd: tracker}
eyes: right
scene:
  - {id: back, kind: disc, size_deg: 3, centre_deg: [10, 0], depth: {D: 0.25}, surface: {kind: solid, rgb: [0.2, 0.6, 1]}}
  - {id: front, kind: disc, size_deg: 3, centre_deg: [10, 0], depth: {factor: [base_D, extra_D]},
     surface: {kind: white_noise, grain_deg: 0.1, mean: 0.5, contrast: 1}}
  - id: dot
    kind: fixation_target
    size_deg: 0.4
    depth: {D: 0.25}
    rgb: [1, 1, 1]
    centre_rgb: [0, 0, 0]
    centre_deg: {eccentricity_deg: {factor: dot_ecc_deg}, meridian_deg: 180}
trial:
  phases:
    - {kind: interval, duration_s: 1}
    - {kind: blank, duration_s: 0.3, show: [dot]}
    - {kind: interval, duration_s: 1}
    - {kind: response, expected_s: 1}
design:
  factors:
    base_D: {levels: [0.5]}
    extra_D: {levels: [0, 0.4]}
    dot_ecc_deg: {levels: [0, 8]}
  repetitions: 3
  randomisation: {kind: full}
response:
  kind: two_interval
  question: Which interval had the nearer front disc?
  test: {mode: ocular}
  reference: {mode: ocular, set: {extra_D: 0}}
  level_factor: extra_D
  order: balanced
observer:
  kind: psychometric_2afc
  eye: {raw_stream: every_sample}
  level_column: extra_D
  threshold_D: 0.3
  width_D: 0.2
  lapse: 0.02
"""


def _session(tmp_path: Path, text: str) -> Path:
    protocols = tmp_path / "protocols"
    protocols.mkdir()
    (protocols / "fixdot.yaml").write_text(text)
    data = tmp_path / "data"
    assert cli_main(["simulate", "--data", str(data), "--protocols", str(protocols), "--participants", "1",
                     "--jobs", "1"]) == 0
    return data / "fixdot" / "sub-S01" / "ses-1"


def test_the_observer_fixates_a_static_target_where_each_trial_draws_it(tmp_path: Path) -> None:
    session = _session(tmp_path, PROTOCOL)
    meta = json.loads((session / "session.json").read_text())
    assert [p["gaze"] for p in meta["phases"]] == ["fixate", "fixate", "fixate"]
    assert meta["fixation_point"] == {"centre_deg": {"eccentricity_deg": {"factor": "dot_ecc_deg"},
                                                     "meridian_deg": 180.0}, "id": "dot"}
    trials = pd.read_parquet(session / "trials.parquet")
    gaze = pd.read_parquet(session / "gaze.parquet")
    assert len(trials) == 12
    for row in trials.itertuples():
        during = gaze[(gaze["trial"] == row.trial) & gaze["gaze_valid"]]
        az_deg, _ = fick_angles_deg(during[["fixation_x_m", "fixation_y_m", "fixation_z_m"]].to_numpy())
        # meridian 180: the dot is to the left, at -dot_ecc_deg azimuth; the tracker's error model is ~1-2 deg
        assert len(during) > 100 and abs(float(np.median(az_deg)) + row.dot_ecc_deg) < 3.0, (row.trial, row.dot_ecc_deg)
    measures, _ = measure_session(session)
    assert measures["accuracy_fixation_mean_deg"].notna().all()
    assert (measures["accuracy_fixation_mean_deg"] < 3.0).all()
    assert measures["precision_rms_s2s_deg"].notna().all()
    # no drift recalibration phase: no drift offset is invented from the target phases
    assert measures["accuracy_fixation_corrected_mean_deg"].isna().all()


def test_a_scene_without_a_fixation_target_is_still_free_viewing(tmp_path: Path) -> None:
    text = PROTOCOL.replace("    - {kind: blank, duration_s: 0.3, show: [dot]}\n", "    - {kind: blank, duration_s: 0.3}\n")
    start = text.index("  - id: dot")
    text = text[:start] + text[text.index("trial:"):]
    text = text.replace("    dot_ecc_deg: {levels: [0, 8]}\n", "")
    session = _session(tmp_path, text)
    meta = json.loads((session / "session.json").read_text())
    assert [p["gaze"] for p in meta["phases"]] == ["free", "free", "free"]
    assert "fixation_point" not in meta
