"""Per-trial gaze quality (issue 12 item 4): a trial whose share of frames with valid gaze is
below the protocol's ``trial.min_valid_gaze_share`` is marked ``gaze_ok`` false in
trials.parquet, listed in session.json, warned about by run/recover and counted (or dropped)
by the analysis loader."""

from __future__ import annotations

import json
import re
import warnings
from pathlib import Path

import pandas as pd
import pytest
from session_helpers import fast_protocol

from psyop import datacontract as dc
from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.session.gaze.simulated import SimulatedTrackerConfig
from psyop.session.plan import compile_plan
from psyop.run.runner import SessionOptions, run_session
from psyop.statistics.dataset import LowGazeWarning, load_dataset

#: Poisson 1 s dropouts at 0.5 Hz over 2 s trials: some trials lose most of their gaze, some none
FAULTS = SimulatedTrackerConfig(dropout_rate_hz=0.5, dropout_s=1.0, blink_rate_hz=0.0)


def _protocol(directory: Path, threshold: float | None) -> Path:
    path = fast_protocol(directory, "detection", 1, phase_s=0.5)
    if threshold is not None:
        text, n = re.subn(r"(?m)^trial:\n", f"trial:\n  min_valid_gaze_share: {threshold}\n", path.read_text())
        assert n == 1
        path.write_text(text)
    return path


def _run(tmp_path: Path, threshold: float | None, name: str) -> tuple[Path, pd.DataFrame, pd.DataFrame]:
    directory = tmp_path / name
    directory.mkdir()
    protocol = load_protocol(_protocol(directory, threshold))
    options = SessionOptions(participant="Q1", seed=5, data_root=directory / "data", progress=False,
                             tracker_faults=FAULTS, every_frame=True, render="cameras")
    assert run_session(protocol, compile_schedule, options).status == "complete"
    session = directory / "data" / "detection" / "sub-Q1" / "ses-1"
    return session, pd.read_parquet(session / "trials.parquet"), pd.read_parquet(session / "frames.parquet")


def _share_from_frames(frames: pd.DataFrame) -> pd.Series:
    return frames.groupby("trial")["gaze_valid"].mean()


def test_protocol_field_defaults_to_half_and_is_bounded(tmp_path: Path) -> None:
    from psyop.errors import UserError

    assert compile_plan(load_protocol(_protocol(tmp_path, None))).min_valid_gaze_share == 0.5
    assert compile_plan(load_protocol(_protocol(tmp_path, 0.8))).min_valid_gaze_share == 0.8
    for bad in (1.5, -0.1):
        with pytest.raises(UserError, match="min_valid_gaze_share"):
            load_protocol(_protocol(tmp_path, bad))


def test_faulty_tracker_marks_exactly_the_low_gaze_trials(tmp_path: Path) -> None:
    session, trials, frames = _run(tmp_path, None, "default")
    share = _share_from_frames(frames)
    by_trial = trials.set_index("trial")
    pd.testing.assert_series_equal(by_trial["gaze_valid_fraction"], share, check_names=False)
    expected = sorted(int(t) for t in share.index[share < 0.5])
    assert 0 < len(expected) < len(trials), "the faults must give both low and good trials"
    assert sorted(int(t) for t in by_trial.index[~by_trial["gaze_ok"].astype(bool)]) == expected
    meta = json.loads((session / "session.json").read_text())
    assert meta["min_valid_gaze_share"] == 0.5
    assert meta["integrity"]["low_gaze_trials"] == expected
    assert meta["integrity"]["min_valid_gaze_share"] == 0.5


def test_protocol_threshold_changes_which_trials_are_marked(tmp_path: Path) -> None:
    _, low_trials, frames = _run(tmp_path, 0.2, "low")
    session, high_trials, _ = _run(tmp_path, 0.95, "high")
    share = _share_from_frames(frames)  # same seed and faults: the same gaze in both sessions
    marked_low = set(low_trials.loc[~low_trials["gaze_ok"].astype(bool), "trial"])
    marked_high = set(high_trials.loc[~high_trials["gaze_ok"].astype(bool), "trial"])
    assert marked_low == set(share.index[share < 0.2])
    assert marked_high == set(share.index[share < 0.95])
    assert marked_low < marked_high
    meta = json.loads((session / "session.json").read_text())
    assert meta["integrity"]["min_valid_gaze_share"] == 0.95
    assert meta["integrity"]["low_gaze_trials"] == sorted(int(t) for t in marked_high)


def test_run_and_recover_warn_with_the_protocol_threshold(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import psyop.run.runner  # noqa: F401 - before capsys swaps sys.stderr
    from psyop.cli import main as cli_main

    protocol = _protocol(tmp_path, 0.9)
    data = tmp_path / "data"
    code = cli_main(["run", str(protocol), "--participant", "W1", "--data", str(data), "--no-progress",
                     "--render", "cameras", "--sim-dropout-rate-hz", "0.6"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    trials = pd.read_parquet(data / "detection" / "sub-W1" / "ses-1" / "trials.parquet")
    n_low = int((~trials["gaze_ok"].fillna(True).astype(bool)).sum())
    assert n_low > 0
    assert f"warning: {n_low} trials had less than 90% valid gaze" in captured.err
    session_json = data / "detection" / "sub-W1" / "ses-1" / "session.json"
    meta = json.loads(session_json.read_text())
    meta["status"] = "incomplete"  # make recover finalise it again
    session_json.write_text(json.dumps(meta))
    assert cli_main(["recover", str(data)]) == 0
    assert f"warning: {n_low} trials had less than 90% valid gaze" in capsys.readouterr().out


def test_analysis_keeps_and_counts_low_gaze_trials_or_drops_them(tmp_path: Path) -> None:
    _, trials, _ = _run(tmp_path, None, "analysis")
    root = tmp_path / "analysis" / "data"
    n_low = int((~trials["gaze_ok"].astype(bool)).sum())
    with pytest.warns(LowGazeWarning, match=f"{n_low} of {len(trials)} trials"):
        kept = load_dataset(root, "detection").trials
    assert len(kept) == len(trials) and kept.attrs["n_low_gaze"] == n_low and kept.attrs["n_low_gaze_dropped"] == 0
    with pytest.warns(LowGazeWarning, match="left out"):
        dropped = load_dataset(root, "detection", drop_low_gaze=True).trials
    assert len(dropped) == len(trials) - n_low and dropped["gaze_ok"].astype(bool).all()
    assert dropped.attrs["n_low_gaze_dropped"] == n_low


def test_sessions_logged_before_gaze_ok_still_load(tmp_path: Path) -> None:
    """Old trials.parquet has gaze_valid_fraction only: judged by the default threshold."""
    from psyop.statistics.dataset import write_dataset

    old = pd.DataFrame({"trial": [0, 1, 2], "study": "s", "participant": "P1", "session": 1,
                        "response": "1", "gaze_valid_fraction": [0.9, 0.2, None]})
    new = old.assign(participant="P2", gaze_ok=[True, False, None])
    write_dataset(tmp_path, {"s": old}, simulated=True)
    write_dataset(tmp_path / "mixed", {"s": old}, simulated=True)  # one old session file ...
    write_dataset(tmp_path / "mixed", {"s": new}, simulated=True)  # ... and one with gaze_ok
    with pytest.warns(LowGazeWarning, match="1 of 3"):
        assert load_dataset(tmp_path, "s").trials.attrs["n_low_gaze"] == 1
    with pytest.warns(LowGazeWarning, match="2 of 6"):
        assert load_dataset(tmp_path / "mixed", "s").trials.attrs["n_low_gaze"] == 2
    clean = old.assign(gaze_valid_fraction=[0.9, 0.8, None])
    write_dataset(tmp_path / "clean", {"s": clean}, simulated=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert load_dataset(tmp_path / "clean", "s").trials.attrs["n_low_gaze"] == 0
    assert dc.low_gaze_mask(clean).tolist() == [False, False, False]
