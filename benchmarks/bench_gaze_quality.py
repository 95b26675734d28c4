"""Gaze quality and event detection (psyop.quality, issue 27): seconds per 10^6 raw samples.

A simulated stream (cross 1 s, pursuit 2.5 s, free viewing 1.5 s, cross 1 s per 6 s trial, 120 Hz,
every sample) is put on its grid, events are detected with pymovements and the per-trial measures
computed; the report gives each step's time per 10^6 samples.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pandas as pd

from psyop.protocol import load_protocol
from psyop.quality.events import EventMethod, detect_events
from psyop.quality.measures import trial_measures
from psyop.quality.samples import gaze_grid
from psyop.session.gaze.plan import FixationPlan, circling_target
from psyop.session.gaze.simulated import SimulatedTracker, SimulatedTrackerConfig
from psyop.session.plan import compile_plan

PROTOCOLS = Path(__file__).resolve().parents[1] / "protocols"


def _stream(n_trials: int) -> tuple[pd.DataFrame, pd.DataFrame]:
    tracker = SimulatedTracker(7, SimulatedTrackerConfig(raw_stream="every_sample"))
    for i in range(n_trials):
        start = 6.0 * i
        tracker.set_plan(FixationPlan("cross", start))
        tracker.set_plan(FixationPlan("pursuit", start + 1.0, target=circling_target(16.0, 90.0, 10.0 * i)))
        tracker.set_plan(FixationPlan("free", start + 3.5, seed=i))
        tracker.set_plan(FixationPlan("cross", start + 5.0))
        tracker.latest(start + 5.99)
    raw = tracker.drain_raw()
    f = np.array([s.fixation_m for s in raw])
    gaze = pd.DataFrame({"gaze_sample_t_s": [s.t_s for s in raw], "gaze_valid": [s.valid for s in raw],
                         "fixation_x_m": f[:, 0], "fixation_y_m": f[:, 1], "fixation_z_m": f[:, 2]})
    trials = pd.DataFrame({"trial": np.arange(n_trials), "trial_start_s": 6.0 * np.arange(n_trials),
                           "trial_end_s": 6.0 * np.arange(n_trials) + 6.0, "trial_seed": np.arange(n_trials)})
    return gaze, trials


def run(out_dir: Path, quick: bool) -> str:
    n_trials = 100 if quick else 400
    gaze, trials = _stream(n_trials)
    plan = compile_plan(load_protocol(PROTOCOLS / "detection.yaml"))
    warm = gaze_grid(gaze.iloc[:600], 120.0)  # imports (pymovements, polars) outside the timing
    detect_events(warm.t_s, warm.az_deg, warm.el_deg, 120.0, EventMethod())
    t0 = time.perf_counter()
    grid = gaze_grid(gaze, 120.0)
    t1 = time.perf_counter()
    detect_events(grid.t_s, grid.az_deg, grid.el_deg, grid.rate_hz, EventMethod())
    t2 = time.perf_counter()
    trial_measures(grid, trials, plan)  # events again, then the measures
    t3 = time.perf_counter()
    per = 1e6 / len(gaze)
    rebuilt_s, n_rebuilt, n_checked = _rebuild(out_dir, 1 if quick else 3)
    return "\n".join([
        "## Gaze quality and events (bench_gaze_quality)",
        "",
        f"{len(gaze):,} simulated 120 Hz samples ({n_trials} trials of 6 s: cross, pursuit, free viewing, cross), "
        "one run each after a warm-up call; seconds per 10^6 samples.",
        "",
        "| step | per 10^6 samples |",
        "|---|---:|",
        f"| grid (psyop.quality.samples) | {(t1 - t0) * per:.2f} s |",
        f"| events (pymovements ivt + microsaccades, amplitude, peak velocity) | {(t2 - t1) * per:.2f} s |",
        f"| events + per-trial measures (trial_measures) | {(t3 - t2) * per:.2f} s |",
        f"| rebuild a requested session's stream from its seed and check it (psyop.quality.resimulate; "
        f"{n_rebuilt:,} samples of a simulated detection session, checked against its {n_checked} recorded ones) | "
        f"{rebuilt_s * 1e6 / n_rebuilt:.2f} s |",
    ])


def _rebuild(out_dir: Path, repetitions: int) -> tuple[float, int, int]:
    """(seconds, samples rebuilt, recorded samples checked) of one rebuild of a simulated detection session."""
    import re
    import shutil

    from psyop.quality.resimulate import resimulate_gaze
    from psyop.quality.session import session_gaze
    from psyop.run.runner import SessionOptions, run_session
    from psyop.schedule import compile_schedule
    from psyop.session.log.record import read_record_file

    work = out_dir / "bench_gaze_quality_rebuild"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    text = re.sub(r"(?m)^(\s*repetitions:)\s*\d+", rf"\g<1> {repetitions}", (PROTOCOLS / "detection.yaml").read_text())
    (work / "detection.yaml").write_text(text)
    options = SessionOptions(participant="B1", seed=3, data_root=work / "data", progress=False, render="cameras")
    run_session(load_protocol(work / "detection.yaml"), compile_schedule, options)
    session = work / "data" / "detection" / "sub-B1" / "ses-1"
    s = session_gaze(session)  # (the imports, once)
    record = read_record_file(session / "session.json")
    assert record is not None
    recorded = pd.read_parquet(session / "gaze.parquet")
    t0 = time.perf_counter()
    r = resimulate_gaze(s.plan, record, "B1", s.trials, recorded)
    seconds = time.perf_counter() - t0
    assert r.gaze is not None, r.reason
    shutil.rmtree(work, ignore_errors=True)
    return seconds, len(r.gaze), r.n_checked
