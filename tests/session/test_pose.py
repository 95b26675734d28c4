"""Head and hand pose: hold-last-valid, the simulation, logging, and replay of reaches."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation
from session_helpers import fast_protocol, small_protocol

from psyop.cli import main as cli_main
from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.session.clock import VirtualClock
from psyop.session.loop import LoopConfig, TrialLoop
from psyop.session.pose import (
    PoseConditioner,
    PoseSample,
    SimulatedPose,
    SimulatedPoseConfig,
    quaternion_from_yaw_pitch_roll,
    reach_from_positions,
)
from psyop.session.reach import horizontal_reach_m
from psyop.session.responses.base import Response
from psyop.run.runner import SessionOptions, run_session

HEAD = ["head_x_m", "head_y_m", "head_z_m", "head_qw", "head_qx", "head_qy", "head_qz"]


def _session(root: Path, study: str, participant: str) -> Path:
    return root / study / f"sub-{participant}" / "ses-1"


def test_conditioner_holds_the_last_valid_pose_and_flags_it() -> None:
    cond = PoseConditioner()
    first = cond.condition(None)
    assert first.held and not first.valid and first.position_m == (0.0, 0.0, 0.0)  # origin before any valid
    good = PoseSample(1.0, (0.1, 0.2, 0.3), quaternion_from_yaw_pitch_roll(0.1, 0.0, 0.0))
    assert cond.condition(good) == cond.condition(good) and not cond.condition(good).held
    bad = [
        PoseSample(2.0, (9.0, 9.0, 9.0), valid=False),  # flagged by the tracker
        PoseSample(3.0, (math.nan, 0.0, 0.0)),  # non-finite
        PoseSample(4.0, (9.0, 9.0, 9.0), (2.0, 0.0, 0.0, 0.0)),  # not a unit quaternion
        None,  # nothing yet
    ]
    for sample in bad:
        out = cond.condition(sample)
        assert out.held and not out.valid
        assert out.position_m == good.position_m and out.orientation_wxyz == good.orientation_wxyz
    assert all(math.isnan(v) for v in PoseConditioner((math.nan,) * 3).condition(None).position_m)


def test_quaternion_matches_scipy_and_simulated_head_is_small_and_stateless() -> None:
    for angles in [(0.3, -0.2, 0.1), (-1.0, 0.5, 2.0)]:
        x, y, z, w = Rotation.from_euler("YXZ", angles).as_quat()
        np.testing.assert_allclose(quaternion_from_yaw_pitch_roll(*angles), (w, x, y, z), atol=1e-12)
    pose = SimulatedPose(7)
    times = np.linspace(0.0, 120.0, 500)
    heads = [pose.head(t) for t in times]
    positions = np.array([h.position_m for h in heads])
    assert all(h.usable() for h in heads)
    assert 0.0005 < positions.std(axis=0).max() and np.abs(positions).max() < 0.02  # sways by mm, not cm
    angle_deg = np.degrees([2 * math.acos(min(1.0, h.orientation_wxyz[0])) for h in heads])
    assert 0.05 < angle_deg.max() < 2.0
    assert SimulatedPose(7).head(33.3) == pose.head(33.3) != SimulatedPose(8).head(33.3)  # a function of (seed, t)


def test_invalid_hand_samples_are_held_flagged_and_the_reach_uses_the_held_values() -> None:
    pose = SimulatedPose(3, SimulatedPoseConfig(hand_dropout_p=0.4))
    loop = TrialLoop(identity={"study": "t", "participant": "P", "session": 1}, phases=(), clock=VirtualClock(),
                     gaze=None, responses=None, renderer=None, display=None, store=None,  # type: ignore[arg-type]
                     config=LoopConfig(progress=False, hand_last_n=10), pose=pose)
    endpoint = (0.0, -0.07, -0.5)
    extras = (("hand_x_m", endpoint[0]), ("hand_y_m", endpoint[1]), ("hand_z_m", endpoint[2]))
    n_held = n_reaches = 0
    for trial in range(6):
        response, cols = loop._track_reach({"trial": trial, "trial_seed": 100 + trial}, Response("x", reach_m=0.5, extras=extras),
                                           end_s=10.0 * (trial + 1))
        xyz = np.column_stack([cols["hand_sample_x_m"], cols["hand_sample_y_m"], cols["hand_sample_z_m"]])
        held, valid = np.array(cols["hand_sample_held"]), np.array(cols["hand_sample_valid"])
        assert len(xyz) == 10 and (held == ~valid).all()
        n_held += int(held.sum())
        for i in np.flatnonzero(held):
            if i > 0:  # a held sample repeats the one before it (held or not)
                np.testing.assert_array_equal(xyz[i], xyz[i - 1])
        np.testing.assert_allclose(np.diff(cols["hand_sample_t_s"]), 1 / 120.0)
        _, mean = reach_from_positions(xyz, 10)
        reach = horizontal_reach_m(mean)  # along the horizontal eye-to-target direction, as the paper's supplement
        if np.isfinite(reach):
            n_reaches += 1
            assert response.reach_m == reach and response.response == f"{reach:.6f}"
            assert abs(reach - 0.5) < 0.003
            assert dict(response.extras)["hand_x_m"] == mean[0]
    assert n_held >= 10 and loop.n_hand_held == n_held and n_reaches >= 4


def test_replayed_pose_reproduces_the_logged_reaches_exactly(tmp_path: Path) -> None:
    protocol = small_protocol(tmp_path, "egocentric", 1)
    common = ["run", str(protocol), "--data", str(tmp_path / "data"), "--no-progress"]
    assert cli_main([*common, "--participant", "A1", "--seed", "3"]) == 0
    original = _session(tmp_path / "data", "egocentric", "A1")
    # another participant, same schedule (same protocol and seed): the hand comes from A1's log
    assert cli_main([*common, "--participant", "B1", "--seed", "3", "--pose", f"replay:{original}"]) == 0
    assert cli_main([*common, "--participant", "C1", "--seed", "3"]) == 0
    a, b, c = (pd.read_parquet(_session(tmp_path / "data", "egocentric", p) / "trials.parquet") for p in ("A1", "B1", "C1"))
    assert len(a) == len(b) > 5
    assert b["reach_m"].tolist() == a["reach_m"].tolist() and b["response"].tolist() == a["response"].tolist()
    assert not np.allclose(c["reach_m"], a["reach_m"])  # without replay the reaches differ
    for _, row in a.iterrows():  # the reach is recomputed from the logged hand samples
        xyz = np.column_stack([row["hand_sample_x_m"], row["hand_sample_y_m"], row["hand_sample_z_m"]])
        assert len(xyz) == 10 and row["hand_sample_valid"].all()
        assert horizontal_reach_m(reach_from_positions(xyz, 10)[1]) == row["reach_m"]
    frames = pd.read_parquet(original / "frames.parquet")
    assert len(frames) and np.isfinite(frames[HEAD].to_numpy(dtype=float)).all()


def test_replay_refuses_a_source_with_another_schedule_unless_mapped_by_condition(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 13: replaying a session of another seed paired a reach made to a 0.50 target with a
    0.90 target, silently. Now: exit 2 naming what differs; by condition, targets match."""
    protocol = small_protocol(tmp_path, "egocentric", 1)
    common = ["run", str(protocol), "--data", str(tmp_path / "data"), "--no-progress"]
    assert cli_main([*common, "--participant", "A1", "--seed", "3"]) == 0
    original = _session(tmp_path / "data", "egocentric", "A1")
    capsys.readouterr()
    assert cli_main([*common, "--participant", "B1", "--seed", "8", "--pose", f"replay:{original}"]) == 2
    err = capsys.readouterr().err
    assert "another schedule" in err and "seed 3 vs 8" in err and "replay-by-condition" in err
    assert not (tmp_path / "data" / "egocentric" / "sub-B1").exists() or not any(
        (tmp_path / "data" / "egocentric" / "sub-B1").rglob("trials.parquet"))
    other = tmp_path / "other.yaml"  # same seed, another protocol text: refused too
    other.write_text(protocol.read_text() + "\n# edited\n")
    assert cli_main(["run", str(other), "--data", str(tmp_path / "data"), "--no-progress", "--participant", "B2",
                     "--seed", "3", "--pose", f"replay:{original}"]) == 2
    assert "protocol hash" in capsys.readouterr().err

    assert cli_main([*common, "--participant", "B1", "--seed", "8", "--pose", f"replay-by-condition:{original}"]) == 0
    a = pd.read_parquet(original / "trials.parquet")
    b = pd.read_parquet(_session(tmp_path / "data", "egocentric", "B1") / "trials.parquet")
    assert a["condition"].tolist() != b["condition"].tolist()  # really another order
    for condition, group in b.groupby("condition"):  # each reach replays one made to the same target
        logged = a[a["condition"] == condition].sort_values("trial")["reach_m"].tolist()
        replayed = group.sort_values("trial")["reach_m"].tolist()
        assert replayed == [logged[j % len(logged)] for j in range(len(replayed))]
    import json

    summary = json.loads((_session(tmp_path / "data", "egocentric", "B1") / "session.json").read_text())
    assert summary["summary"]["pose"]["hand_trials_reused"] == len(b) - b["condition"].map(
        a["condition"].value_counts()).clip(upper=b["condition"].map(b["condition"].value_counts())).groupby(
        b["condition"]).first().sum()  # counted, never silent


def test_replay_of_a_missing_session_names_it_without_suggesting_recover(tmp_path: Path, capsys) -> None:
    protocol = small_protocol(tmp_path, "egocentric", 1)
    assert cli_main(["run", str(protocol), "--data", str(tmp_path / "d"), "--no-progress", "--participant", "X1",
                     "--pose", f"replay:{tmp_path / 'data' / 'egocentric' / 'sub-sim01'}"]) == 2
    err = capsys.readouterr().err
    assert "no such session directory" in err and "recover" not in err


def test_head_pose_is_logged_every_frame_and_replays(tmp_path: Path) -> None:
    protocol = load_protocol(fast_protocol(tmp_path, "detection", 1, phase_s=0.1))
    opts = dict(participant="H1", seed=2, progress=False, every_frame=True, render="cameras")
    assert run_session(protocol, compile_schedule, SessionOptions(data_root=tmp_path / "a", **opts)).status == "complete"
    a = pd.read_parquet(_session(tmp_path / "a", "detection", "H1") / "frames.parquet")
    values = a[HEAD].to_numpy(dtype=float)
    assert len(a) > 50 and np.isfinite(values).all() and a["head_valid"].all() and not a["head_held"].any()
    np.testing.assert_allclose(np.linalg.norm(values[:, 3:], axis=1), 1.0, atol=1e-12)
    assert values[:, 0].std() > 0  # the head moves
    np.testing.assert_array_equal(a["head_sample_t_s"], a["render_start_s"])  # sampled at the frame
    replay = SessionOptions(data_root=tmp_path / "b", pose=f"replay:{_session(tmp_path / 'a', 'detection', 'H1')}", **opts)
    assert run_session(protocol, compile_schedule, replay).status == "complete"
    b = pd.read_parquet(_session(tmp_path / "b", "detection", "H1") / "frames.parquet")
    np.testing.assert_array_equal(b[HEAD].to_numpy(dtype=float), values)


def test_bad_pose_option_is_a_user_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    protocol = small_protocol(tmp_path, "detection", 1)
    for spec, says in [(f"replay:{tmp_path / 'missing'}", "no such session directory"), ("replay:", "SESSION_DIR"), ("vive", "unknown pose")]:
        assert cli_main(["run", str(protocol), "--participant", "X1", "--data", str(tmp_path / "d"), "--no-progress",
                         "--pose", spec]) == 2
        assert says in capsys.readouterr().err
