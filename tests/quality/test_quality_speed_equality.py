"""The span-based trial measures equal their former per-sample forms (tests/quality/former_measures.py)
exactly on the same sessions, and the stream rebuilt for a whole run at once its former phase-by-phase
rebuild; the simulated eye's free-viewing fixations drawn to a shorter horizon are the start of the longer
list; the quality cache returns exactly what was measured and never a stale entry."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest

from psyop.protocol import load_protocol
from psyop.quality.cache import QualityCache, code_fingerprint
from psyop.quality.measures import _saccade_masks, trial_measures
from psyop.quality.resimulate import in_trial_windows, rebuilt_stream, runs_of
from psyop.quality.samples import gaze_grid
from psyop.quality.session import measure_session, measured_session, session_gaze
from psyop.run.runner import SessionOptions, run_session
from psyop.schedule import compile_schedule
from psyop.session.gaze.plan import FixationPlan
from psyop.session.gaze.simulated import SimulatedTracker, SimulatedTrackerConfig, seed_for, tracker_config
from psyop.session.log.record import read_record_file
from tests.quality import former_measures as former
from tests.session.session_helpers import small_protocol

pytestmark = pytest.mark.cross_cpu  # the former and the span-based forms on this CPU's kernels, compared exactly


def _session(directory: Path, study: str) -> Path:
    """A shipped protocol with one repetition per condition, simulated (its requested stream rebuilt)."""
    options = SessionOptions(participant="P1", seed=11, data_root=directory / "data", progress=False, render="cameras")
    assert run_session(load_protocol(small_protocol(directory, study, 1)), compile_schedule, options).status == "complete"
    return directory / "data" / study / "sub-P1" / "ses-1"


@pytest.fixture(scope="module")
def sessions(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """detection (cross and pursuit phases, blinks) and ordinal (free viewing)."""
    return {study: _session(tmp_path_factory.mktemp(study), study) for study in ("detection", "ordinal")}


@pytest.mark.parametrize("study", ["detection", "ordinal"])
def test_trial_measures_equal_the_former_per_sample_form(sessions: dict[str, Path], study: str) -> None:
    s = session_gaze(sessions[study])
    assert s.stream == "resimulated"
    for run, trials in runs_of(s.trials):
        grid = gaze_grid(s.gaze[s.gaze["run"] == run], s.rate_hz)
        new, new_events = trial_measures(grid, trials, s.plan)
        old, old_events = former.trial_measures(grid, trials, s.plan)
        assert len(new) == len(trials) and len(new_events) > 0
        pd.testing.assert_frame_equal(new, old, check_exact=True)  # tolerance 0: the same arithmetic, indexed apart
        pd.testing.assert_frame_equal(new_events, old_events, check_exact=True)


@pytest.mark.parametrize("study", ["detection", "ordinal"])
def test_the_rebuilt_stream_at_once_equals_the_former_phase_by_phase_rebuild(sessions: dict[str, Path],
                                                                            study: str) -> None:
    directory = sessions[study]
    s = session_gaze(directory)
    record = read_record_file(directory / "session.json")
    assert s.stream == "resimulated" and record is not None and record.sim_tracker_faults is not None
    faults = record.sim_tracker_faults
    base = dataclasses.replace(SimulatedTrackerConfig(), dropout_rate_hz=faults.dropout_rate_hz,
                               nan_burst_rate_hz=faults.nan_burst_rate_hz, raw_stream="requested")
    config = tracker_config(s.plan.observer.eye if s.plan.observer is not None else None, s.participant, base)
    overlapping = s.trials.copy()  # a window that begins inside the one before it: rebuilt block by block
    second = overlapping.sort_values("trial_start_s").index[1]
    overlapping.loc[second, "trial_start_s"] -= 0.5
    for trials in (s.trials, overlapping):
        former_tables = [former.run_stream(SimulatedTracker(seed_for(record.seed, "tracker"), config), s.plan, run,
                                           rows) for run, rows in runs_of(trials)]
        now = rebuilt_stream(s.plan, record, s.participant, trials).to_pandas()
        before = pa.concat_tables(former_tables).to_pandas()
        assert len(now) > 1000 and now["gaze_valid"].any() and (~now["gaze_valid"]).any()
        pd.testing.assert_frame_equal(now, before, check_exact=True)  # bit for bit: the same arithmetic per tick


def test_saccade_masks_and_trial_windows_equal_the_former_masks() -> None:
    rng = np.random.default_rng(3)
    t_s = np.arange(2000) / 120.0
    onsets = np.sort(rng.uniform(-1.0, 18.0, 60))
    events = pd.DataFrame({"name": rng.choice(["fixation", "saccade", "microsaccade"], 60), "onset_s": onsets,
                           "offset_s": onsets + rng.uniform(-0.01, 0.2, 60)})  # some end before they start
    for new, old in zip(_saccade_masks(t_s, events), former._saccade_masks(t_s, events)):
        np.testing.assert_array_equal(new, old)
    times = np.concatenate([rng.uniform(-1.0, 20.0, 3000), [np.nan, np.inf, -np.inf, 2.0, 5.0]])
    gaze = pd.DataFrame({"gaze_sample_t_s": times, "run": rng.integers(0, 3, len(times))})
    starts = rng.uniform(0.0, 18.0, 40)
    trials = pd.DataFrame({"trial_start_s": np.concatenate([starts, [np.nan, 4.0, 2.0]]),  # overlapping, empty,
                           "trial_end_s": np.concatenate([starts + rng.uniform(-0.5, 1.5, 40), [3.0, np.nan, 2.0]]),
                           "run": rng.integers(0, 2, 43)})  # NaN and reversed windows among them
    np.testing.assert_array_equal(in_trial_windows(gaze, trials), former.in_trial_windows(gaze, trials))


def test_free_viewing_fixations_to_a_shorter_horizon_start_the_longer_list() -> None:
    plan = FixationPlan("free", 1.5, 1.0, radius_deg=8.0, seed=12345)
    lists = []
    for horizon_s in (0.0, 10.0):
        tracker = SimulatedTracker(7, SimulatedTrackerConfig())
        tracker.set_plan(plan)
        tracker._free_viewing(plan, 1.2, horizon_s=horizon_s)
        assert tracker._fixations is not None
        lists.append(tracker._fixations[1])
    short, long = lists
    assert 1 < len(short) < len(long) and short == long[:len(short)]  # bit for bit
    assert short[-1][0] <= 1.2 < long[len(short)][0]


def test_the_cache_returns_what_was_measured_and_a_changed_file_misses(sessions: dict[str, Path],
                                                                       tmp_path: Path) -> None:
    cache = QualityCache(tmp_path / "cache", code_fingerprint())
    fresh = measured_session(sessions["detection"])
    first = measure_session(sessions["detection"], cache=cache)  # measured and stored
    assert len(list(cache.folder.glob("*.parquet"))) == 2
    again = measure_session(sessions["detection"], cache=cache)  # read back
    for a, b, c in zip(fresh, first, again):
        pd.testing.assert_frame_equal(a, b, check_exact=True)
        pd.testing.assert_frame_equal(a, c, check_exact=True)
    copy = tmp_path / "copy" / "ses-1"
    shutil.copytree(sessions["detection"], copy)
    assert cache.key(copy) == cache.key(sessions["detection"])  # the key is the content, not the place
    trials = copy / "trials.parquet"
    trials.write_bytes(trials.read_bytes()[:-1] + b"\0")  # one byte changed: another key, verified and refused
    assert cache.key(copy) != cache.key(sessions["detection"])
    with pytest.raises(Exception, match="trials.parquet"):
        measure_session(copy, cache=cache)
    assert QualityCache(cache.folder, "another psyop").key(sessions["detection"]) != cache.key(sessions["detection"])


def test_a_cache_that_cannot_be_written_still_measures(sessions: dict[str, Path], tmp_path: Path) -> None:
    blocked = tmp_path / "a file"
    blocked.write_text("")
    cache = QualityCache(blocked / "cache", code_fingerprint())  # a folder under a file cannot be made
    measures, _ = measure_session(sessions["ordinal"], cache=cache)
    assert len(measures) > 0 and not blocked.is_dir()


@pytest.mark.parametrize("study", ["detection", "ordinal"])
def test_the_first_trials_rebuilt_alone_are_the_start_of_the_whole_rebuild(sessions: dict[str, Path],
                                                                           study: str) -> None:
    whole, part = session_gaze(sessions[study]), session_gaze(sessions[study], n_trials=3)
    assert part.stream == whole.stream == "resimulated"
    assert 3 <= len(part.trials) < len(whole.trials)
    pd.testing.assert_frame_equal(part.trials, whole.trials.loc[part.trials.index])
    kept = whole.gaze[whole.gaze["trial"].isin(part.trials["trial"])].reset_index(drop=True)
    assert len(kept) > 100
    pd.testing.assert_frame_equal(part.gaze.reset_index(drop=True), kept, check_exact=True)  # bit for bit
