"""Latency you can set (issue 44 item 2): ``display: {added_latency_ms: N}`` (or a factor) renders each frame
with the newest raw-stream sample at or before (the newest sample's time - N ms), held; the frames record the
added latency and the intrinsic age, and the camera's centre of projection (the nodal point the renderer
places) in frame k is the one computed from the gaze of N ms earlier, within one tracker sample.

Headless, virtual clock, every frame, cameras only; the simulated tracker streams every sample (120 Hz) with
no error, noise or drift, so the raw stream is the eye's pursuit of the circling target (the shipped detection
protocol's path, 90 deg/s at 16 deg) and the single-point recalibration corrects nothing.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from psyop.errors import UserError
from psyop.protocol import load_protocol
from psyop.run.runner import SessionOptions, run_session
from psyop.schedule import compile_schedule
from psyop.session.frames import CameraRenderer
from psyop.session.gaze.delay import DelayedGaze
from psyop.session.gaze.sample import GazeSample, RawGazeSample
from psyop.session.plan import compile_plan

ROOT = Path(__file__).resolve().parents[2]
PERIOD_S = 1.0 / 120.0  # the simulated tracker's sample period
EXACT_EYE = {"raw_stream": "every_sample", "precision_deg": 1e-9, "error_centre_deg": 0.0, "error_per_15deg": 0.0,
             "drift_start_deg": 0.0, "drift_deg_per_min": 0.0, "blink_rate_hz": 0.0, "pursuit_gain": 1.0,
             "pursuit_lag_s": 0.0}


def latency_protocol(tmp_path: Path, added: object, *, bound_ms: float | None = None, name: str = "lat") -> Path:
    """The detection protocol, 2 trials (one per level), the exact eye above, ``display.added_latency_ms: added``."""
    data = yaml.safe_load((ROOT / "protocols" / "detection.yaml").read_text())
    data["study"]["name"] = name
    data["design"]["factors"]["back_D"]["levels"] = [1]
    data["design"]["factors"]["level_D"]["levels"] = [0.25, 0.5]
    data["design"]["repetitions"] = 1
    data["observer"]["eye"] = dict(EXACT_EYE)
    if added is not None:
        data["display"]["added_latency_ms"] = added
    if bound_ms is not None:
        data["trial"]["max_gaze_age_ms"] = bound_ms
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def run(path: Path, root: Path, cameras: list | None = None,
        monkeypatch: pytest.MonkeyPatch | None = None) -> Path:
    """Run ``path`` headless (every frame, cameras only); the cameras each frame computed into ``cameras``."""
    if cameras is not None and monkeypatch is not None:
        original = CameraRenderer.render

        def recording(self, row, phase, mode, t_in_phase_s, fixation_m, head_pose=None, frame=None):
            cameras.append((int(row["trial"]), phase.name, mode,
                            self.rig.camera(self.display, "right", fixation_m, mode, row=row).centre_of_projection_m))
            return original(self, row, phase, mode, t_in_phase_s, fixation_m, head_pose, frame)

        monkeypatch.setattr(CameraRenderer, "render", recording)
    protocol = load_protocol(path)
    outcome = run_session(protocol, compile_schedule, SessionOptions(
        participant="S01", seed=7, data_root=root, progress=False, every_frame=True, render="cameras",
        check_images=0, write_description=False, fsync=False))
    assert outcome.status == "complete", outcome.message
    return root / protocol.study.name / "sub-S01" / "ses-1"


def test_frames_render_the_gaze_of_50_ms_earlier(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    cameras: list = []
    session = run(latency_protocol(tmp_path, 50), tmp_path / "data", cameras, monkeypatch)
    frames = pd.read_parquet(session / "frames.parquet")
    gaze = pd.read_parquet(session / "gaze.parquet").sort_values("gaze_sample_t_s")
    assert np.diff(gaze["gaze_sample_t_s"]).max() < 1.5 * PERIOD_S  # every sample streamed
    assert (frames["added_latency_s"] == 0.05).all()
    rendered = frames[frames["display_should_render"] & frames["phase"].ne("response")].reset_index(drop=True)
    assert len(cameras) == len(rendered)  # one camera per rendered frame (cameras only: no response-phase render)
    newest_t = rendered["display_time_s"] - rendered["gaze_age_intrinsic_s"]
    asked_t = newest_t - 0.05
    used_t = rendered["gaze_sample_t_s"]
    late = rendered["gaze_valid"].to_numpy()
    assert late.mean() > 0.9
    # the sample at or before (newest - 50 ms), held: within one tracker sample of it, never after it
    assert ((asked_t - used_t)[late] >= -1e-9).all() and ((asked_t - used_t)[late] < PERIOD_S + 1e-9).all()
    # ... and it is the raw stream's sample there (the frame's fixation is that sample's: nothing to correct)
    t_raw = gaze["gaze_sample_t_s"].to_numpy()
    index = np.searchsorted(t_raw, asked_t.to_numpy() + 1e-9, side="right") - 1
    raw_xyz = gaze[["fixation_x_m", "fixation_y_m", "fixation_z_m"]].to_numpy()
    assert np.allclose(t_raw[index][late], used_t[late], rtol=0, atol=1e-12)
    assert np.allclose(raw_xyz[index][late], rendered[["fixation_x_m", "fixation_y_m", "fixation_z_m"]][late],
                       rtol=0, atol=1e-9)
    # total = intrinsic + added + less than one sample
    excess = rendered["gaze_age_at_display_s"] - rendered["gaze_age_intrinsic_s"] - 0.05
    assert ((excess[late] > -1e-9) & (excess[late] < PERIOD_S + 1e-9)).all()
    # the nodal point (the camera's centre of projection) of frame k is the one computed from the gaze sample of
    # 50 ms earlier (the one at or before it, less than a tracker sample before), and far from the newest gaze's
    # (6 samples of pursuit away): steady pursuit only (the eye jumps to the target as an interval begins)
    plan = compile_plan(load_protocol(tmp_path / "lat.yaml"))

    def centre(k: int, mode: str) -> np.ndarray:
        return plan.rig.camera(plan.display, "right", tuple(raw_xyz[k]), mode).centre_of_projection_m

    onset = rendered.groupby(["trial", "phase"])["display_time_s"].transform("min")
    steady = [i for i in range(len(rendered)) if late[i] and cameras[i][2] == "ocular"
              and rendered.loc[i, "phase"].startswith("interval") and asked_t[i] - 2 * PERIOD_S > onset[i]]
    assert len(steady) > 100
    newest = np.searchsorted(t_raw, newest_t.to_numpy() + 1e-9, side="right") - 1
    for i in steady:
        got, k, mode = cameras[i][3], index[i], cameras[i][2]
        one_sample = float(np.linalg.norm(centre(k + 1, mode) - centre(k, mode)))
        assert one_sample > 0
        assert np.linalg.norm(got - centre(k, mode)) <= 1e-9
        assert np.linalg.norm(got - centre(newest[i], mode)) > 4 * one_sample


def test_without_added_latency_the_newest_sample_is_rendered(tmp_path: Path) -> None:
    session = run(latency_protocol(tmp_path, None), tmp_path / "data")
    frames = pd.read_parquet(session / "frames.parquet")
    valid = frames["gaze_valid"]
    assert (frames["added_latency_s"] == 0.0).all()
    assert (frames["gaze_age_intrinsic_s"][valid] == frames["gaze_age_at_display_s"][valid]).all()


def test_added_latency_as_a_factor(tmp_path: Path) -> None:
    """``{factor: added_latency_ms}``: each trial adds its level; a bound judges the intrinsic part only."""
    path = latency_protocol(tmp_path, {"factor": "added_latency_ms"}, bound_ms=40, name="latf")
    data = yaml.safe_load(path.read_text())
    data["design"]["factors"]["added_latency_ms"] = {"levels": [0, 100]}
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    session = run(path, tmp_path / "data")
    trials = pd.read_parquet(session / "trials.parquet")
    frames = pd.read_parquet(session / "frames.parquet").merge(trials[["trial", "added_latency_ms"]], on="trial")
    assert np.allclose(frames["added_latency_s"], frames["added_latency_ms"] / 1000.0, rtol=0, atol=0)
    for level, rows in trials.groupby("added_latency_ms"):
        # the virtual clock's intrinsic age: the tracker's 10 ms plus under a sample, plus the frame's wait
        assert ((rows["gaze_age_median_s"] > level / 1000.0 + 0.01) & (rows["gaze_age_median_s"] < level / 1000.0 + 0.04)).all()
        assert (rows["gaze_age_over_share"] == 0.0).all() and rows["gaze_age_ok"].all()


@pytest.mark.parametrize("added, message", [({"factor": "nope_ms"}, "not a factor"),
                                            ({"factor": "back_D"}, "_ms"), (2000, "added_latency_ms")])
def test_added_latency_is_checked(tmp_path: Path, added: object, message: str) -> None:
    with pytest.raises(UserError, match=message):
        load_protocol(latency_protocol(tmp_path, added))


def test_delayed_gaze_holds_the_sample_at_or_before() -> None:
    """The wrapper hands every raw sample on once, keeps them, and answers the newest at or before a time."""

    class Source:  # 100 Hz, every sample streamed
        def __init__(self) -> None:
            self.raw: list[RawGazeSample] = []
            self.sent = 0

        def latest(self, now_s: float) -> GazeSample:
            for k in range(len(self.raw), int(round(now_s * 100)) + 1):
                self.raw.append(RawGazeSample(k / 100, k / 100, k / 100, True, 1.0, (k / 100, 0.0, -1.0)))
            return GazeSample(self.raw[-1].t_s, self.raw[-1].fixation_m, 1.0, True)

        def drain_raw(self) -> list[RawGazeSample]:
            out, self.sent = self.raw[self.sent:], len(self.raw)
            return out

    delayed = DelayedGaze(Source())  # type: ignore[arg-type]
    assert delayed.before(0.0) is None
    newest = delayed.latest(1.0)
    assert newest is not None and newest.timestamp_s == 1.0
    assert delayed.before(1.0 - 0.055).timestamp_s == pytest.approx(0.94)  # held, not interpolated
    assert delayed.before(0.5).timestamp_s == pytest.approx(0.5)
    drained = delayed.drain_raw()
    assert [round(s.t_s, 2) for s in drained] == [round(k / 100, 2) for k in range(101)] and delayed.drain_raw() == []
    delayed.latest(5.0)
    assert delayed.before(0.5) is None  # older than KEEP_S: forgotten
