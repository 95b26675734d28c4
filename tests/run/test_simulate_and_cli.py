"""`psyop simulate` (reduced sizes), `psyop run` options, replay, and user errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
from session_helpers import PROTOCOLS, fast_protocol

from psyop.cli import main as cli_main
from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.run.runner import SessionOptions, run_session


def test_simulate_all_five_studies_reduced(tmp_path: Path) -> None:
    data = tmp_path / "data"
    assert cli_main(["simulate", "--data", str(data), "--protocols", str(PROTOCOLS), "--participants", "1", "--jobs", "2"]) == 0
    description = json.loads((data / "dataset_description.json").read_text())
    assert description["simulated"] is True
    assert sorted(description["studies"]) == ["detection", "discrimination", "egocentric", "ordinal", "realism"]
    for study in description["studies"]:
        session = data / study / "sub-S01" / "ses-1"
        meta = json.loads((session / "session.json").read_text())
        assert meta["simulated"] is True and meta["status"] == "complete"
        trials = pd.read_parquet(session / "trials.parquet")
        assert len(trials) == meta["n_trials_scheduled"]
        assert trials["response"].notna().all()
        frames = pd.read_parquet(session / "frames.parquet")
        assert 0 < len(frames) < len(trials) * 5  # a sampled few, not every frame
        assert frames["image_ok"].all()
        assert 1 <= frames["image_checked"].sum() <= 2  # two images (one stereo frame or two mono) per session
        assert meta["rendering"].startswith("images")
    # its run time is a duration: the full paper-size run is timed in benchmarks/bench_session_latency.py
    # running it again finds everything complete and does no work
    assert cli_main(["simulate", "--data", str(data), "--protocols", str(PROTOCOLS), "--participants", "1", "--jobs", "1"]) == 0


def test_replayed_gaze_reproduces_the_logged_frames(tmp_path: Path) -> None:
    protocol = load_protocol(fast_protocol(tmp_path, "ordinal", 1, phase_s=0.2))
    original = SessionOptions(participant="A1", seed=4, data_root=tmp_path / "a", progress=False, every_frame=True, render="cameras")
    assert run_session(protocol, compile_schedule, original).status == "complete"
    frames_a = pd.read_parquet(tmp_path / "a" / "ordinal" / "sub-A1" / "ses-1" / "frames.parquet")
    replay = SessionOptions(participant="A1", seed=4, data_root=tmp_path / "b", progress=False, every_frame=True, render="cameras",
                            tracker=f"replay:{tmp_path / 'a' / 'ordinal' / 'sub-A1' / 'ses-1'}")
    assert run_session(protocol, compile_schedule, replay).status == "complete"
    frames_b = pd.read_parquet(tmp_path / "b" / "ordinal" / "sub-A1" / "ses-1" / "frames.parquet")
    assert len(frames_a) == len(frames_b)
    live = frames_a["gaze_valid"].to_numpy() & frames_b["gaze_valid"].to_numpy()
    assert live.mean() > 0.8
    np.testing.assert_allclose(frames_b["gaze_sample_t_s"][live], frames_a["gaze_sample_t_s"][live])


def test_run_user_errors(tmp_path: Path, capsys) -> None:
    assert cli_main(["run", str(tmp_path / "missing.yaml"), "--participant", "P1"]) == 2
    assert "protocol file not found" in capsys.readouterr().err
    protocol = PROTOCOLS / "detection.yaml"
    assert cli_main(["run", str(protocol), "--participant", "P_1", "--data", str(tmp_path)]) == 2
    assert "letters and digits" in capsys.readouterr().err
    assert cli_main(["run", str(protocol), "--participant", "P1", "--tracker", "pupil:127.0.0.1:1", "--data", str(tmp_path)]) == 2
    assert "--clock real" in capsys.readouterr().err
    assert cli_main(["run", str(protocol), "--participant", "P1", "--tracker", "bogus", "--data", str(tmp_path)]) == 2
    assert cli_main(["recover", str(tmp_path / "nothing")]) == 2
