"""Session costs: the per-frame software path from gaze sample in to frame submitted,
the per-trial durable append, and a whole simulated dataset at the paper's sizes.

Measured side by side in one run:
- frame path with the gaze-dependent camera computation for both eyes (psyop.optics) vs
  the same path without it (hold/drift filter, logging, submit only); CPU only, the
  image itself is the renderer's cost (bench_rendering_*);
- durable append per trial: fdatasync'd Arrow IPC batch vs the same without sync, and
  with one trial's 495 frame rows (5.5 s at 90 Hz);
- `psyop simulate` of all five studies (paper sizes unless quick) on 2 worker processes.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from psyop.session.clock import RealClock
from psyop.session.frames import CameraRenderer, FrameRecorder, HeadlessDisplay
from psyop.session.gaze.sample import GazeSample
from psyop.session.log.layout import SessionPaths
from psyop.session.log.schema import trial_schema
from psyop.session.log.store import SessionStore
from psyop.session.loop import LoopConfig, TrialLoop
from psyop.session.phases import PhaseSpec

PROTOCOLS = Path(__file__).resolve().parents[1] / "protocols"
FRAME_BUDGET_MS = 1000.0 / 90.0


class _LiveSource:
    """A tracker whose newest sample was taken just now (pure software path)."""

    def __init__(self, clock: RealClock) -> None:
        self.clock = clock
        self.k = 0

    def latest(self, now_s: float) -> GazeSample:
        self.k += 1
        angle = 0.01 * self.k
        return GazeSample(self.clock.now_s(), (0.3 * np.cos(angle), 0.3 * np.sin(angle), -1.0), 0.95, True)

    def start(self) -> None: ...

    def close(self) -> None: ...

    def stats(self) -> dict:
        return {}


def _frame_path_ms(with_camera: bool, n: int, with_pose: bool = False) -> np.ndarray:
    from psyop.optics import VIVE_PRO, get_eye_model
    from psyop.optics.rig import EyeRig
    from psyop.session.pose import SimulatedPose

    clock = RealClock()
    rig = EyeRig(get_eye_model("gullstrand_emsley_relaxed"), 0.063, ("left", "right"))
    renderer = CameraRenderer(VIVE_PRO, rig) if with_camera else None
    loop = TrialLoop(identity={"study": "bench", "participant": "B", "session": 1}, phases=(), clock=clock,
                     gaze=_LiveSource(clock), responses=None, renderer=renderer, display=HeadlessDisplay(clock, 90.0),
                     store=None, config=LoopConfig(progress=False),  # type: ignore[arg-type]
                     pose=SimulatedPose(seed=0) if with_pose else None)
    phase = PhaseSpec("interval1", 2.0, "stimulus", "pursuit", "mode_interval1", interval=1)
    row = {"trial": 0, "mode_interval1": "ocular"}
    frames = FrameRecorder()
    for i in range(50):  # warm-up
        loop._frame(row, phase, frames, i)
    frames = FrameRecorder()
    for i in range(n):
        loop._frame(row, phase, frames, i)
    table = frames.table().to_pandas()
    # sample taken at gaze_sample_t_s (just before), frame submitted at submit_s
    return (table["submit_s"] - table["gaze_sample_t_s"]).to_numpy() * 1e3


def _append_ms(directory: Path, fsync: bool, n: int, frames_per_trial: int) -> np.ndarray:
    schedule = pd.DataFrame({"trial": range(n), "block": 0, "condition": "c", "trial_seed": range(n), "level_D": 0.5,
                             "mode_interval1": "ocular", "mode_interval2": "conventional", "correct_interval": 1})
    paths = SessionPaths(directory, "bench", f"F{int(fsync)}N{frames_per_trial}", 1)
    store = SessionStore(paths, trial_schema(schedule), fsync=fsync)
    store.open({"study": "bench", "seed": 0, "n_trials_scheduled": n})
    frames = FrameRecorder()
    for k in range(frames_per_trial):
        frames.add(trial=0, phase="interval1", frame=k, gaze_sample_t_s=k / 90, fixation_x_m=0.1, fixation_y_m=0.0,
                   fixation_z_m=-1.0, gaze_confidence=0.9, gaze_valid=True, gaze_held=False, render_start_s=k / 90,
                   submit_s=k / 90, sample_age_s=0.01, image_checked=True, image_ok=True)
    table = frames.table() if frames_per_trial else None
    times = []
    for row in schedule.to_dict("records"):
        t0 = time.perf_counter()
        store.append_trial({**row, "response": "1", "correct": True}, table)
        times.append(time.perf_counter() - t0)
    store.close()
    return np.array(times) * 1e3


def _stats(ms: np.ndarray) -> tuple[float, float]:
    return float(np.median(ms)), float(np.percentile(ms, 99))


def run(out_dir: Path, quick: bool) -> str:
    n_frames = 2000 if quick else 20000
    cam = _frame_path_ms(True, n_frames)
    cam_pose = _frame_path_ms(True, n_frames, with_pose=True)
    bare = _frame_path_ms(False, n_frames)
    tmp = Path(tempfile.mkdtemp(prefix="bench_session_"))
    try:
        n_trials = 50 if quick else 300
        appends = {
            ("fdatasync", 0): _append_ms(tmp, True, n_trials, 0),
            ("no sync", 0): _append_ms(tmp, False, n_trials, 0),
            ("fdatasync", 495): _append_ms(tmp, True, n_trials // 2, 495),
            ("no sync", 495): _append_ms(tmp, False, n_trials // 2, 495),
        }
        from psyop.run.simulate import PAPER_PARTICIPANTS, simulate_dataset

        sizes = {k: 1 for k in PAPER_PARTICIPANTS} if quick else None
        start = time.perf_counter()
        results = simulate_dataset(sorted(PROTOCOLS.glob("*.yaml")), tmp / "sim", jobs=2, participants=sizes)
        sim_s = time.perf_counter() - start
        n_sim_trials = sum(r[3] for r in results)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    cam_med, cam_p99 = _stats(cam)
    bare_med, bare_p99 = _stats(bare)
    pose_med, pose_p99 = _stats(cam_pose)
    lines = [
        "## Session: per-frame software latency, durable append, simulated dataset",
        "",
        f"Per-frame software path, gaze sample in -> frame submitted (CPU, {n_frames} frames, headless, no image):",
        "",
        "| path | median ms | p99 ms | median / 11.1 ms frame | p99 / frame |",
        "|---|---|---|---|---|",
        f"| filter + both eyes' cameras + log + submit | {cam_med:.4f} | {cam_p99:.4f} | {cam_med / FRAME_BUDGET_MS:.2%} | {cam_p99 / FRAME_BUDGET_MS:.2%} |",
        f"| as above + simulated head pose per frame | {pose_med:.4f} | {pose_p99:.4f} | {pose_med / FRAME_BUDGET_MS:.2%} | {pose_p99 / FRAME_BUDGET_MS:.2%} |",
        f"| filter + log + submit (no camera) | {bare_med:.4f} | {bare_p99:.4f} | {bare_med / FRAME_BUDGET_MS:.2%} | {bare_p99 / FRAME_BUDGET_MS:.2%} |",
        "",
        f"Camera computation share of the path: {cam_med / bare_med:.1f}x the bare path (median).",
        "",
        "Durable append per trial (Arrow IPC batch; frames batch first when present):",
        "",
        "| sync | frame rows | median ms | p99 ms | ratio to unsynced |",
        "|---|---|---|---|---|",
    ]
    for frames_per_trial in (0, 495):
        base = np.median(appends[("no sync", frames_per_trial)])
        for sync in ("fdatasync", "no sync"):
            med, p99 = _stats(appends[(sync, frames_per_trial)])
            lines.append(f"| {sync} | {frames_per_trial} | {med:.3f} | {p99:.3f} | {med / base:.1f}x |")
    label = "1 participant per study (quick)" if quick else "paper sizes (6/6/19/13/19 participants)"
    lines += [
        "",
        f"`psyop simulate`, all five studies, {label}, 2 worker processes: {len(results)} sessions, "
        f"{n_sim_trials} trials in {sim_s:.1f} s wall ({n_sim_trials / sim_s:.0f} trials/s; includes the per-trial fdatasync).",
    ]
    return "\n".join(lines)
