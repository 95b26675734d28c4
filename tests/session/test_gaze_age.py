"""Latency you can see (issue 44 item 1): per trial the intervals' gaze-to-photon age (median, p95, max of the
frames' ``gaze_age_at_display_s``, frames with valid gaze), the share over the protocol's
``trial.max_gaze_age_ms`` and ``gaze_age_ok``; session.json's ``summary.gaze_age`` and ``integrity``;
``psyop timing``'s lines and figure; the analysis counting (and on request dropping) the late trials like the
low-gaze ones; the methods sentence."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from psyop.session.latency import GAZE_AGE_COLUMNS, GazeLatency, trial_columns

from test_added_latency import latency_protocol, run

BOUND_MS = 14.0  # the virtual clock's age: the tracker's 10 ms plus up to one 120 Hz sample: about half over it


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("gaze_age")
    import yaml

    path = latency_protocol(tmp, None, bound_ms=BOUND_MS, name="age")
    data = yaml.safe_load(path.read_text())
    data["observer"]["eye"] = {"raw_stream": "requested", "blink_rate_hz": 1.0}  # blinks: some frames held
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return run(path, tmp / "data")


def _expected(frames: pd.DataFrame, meta: dict) -> pd.DataFrame:
    """The per-trial columns computed here from the frames, independently of psyop.session.latency."""
    kind = {p["name"]: p["show"] for p in meta["phases"]}
    used = frames[frames["phase"].map(kind).eq("stimulus") & frames["gaze_valid"]]
    return used.groupby("trial").agg(
        gaze_age_median_s=("gaze_age_at_display_s", "median"),
        gaze_age_p95_s=("gaze_age_at_display_s", lambda a: float(np.percentile(a, 95))),
        gaze_age_max_s=("gaze_age_at_display_s", "max"),
        gaze_age_over_share=("gaze_age_intrinsic_s", lambda a: float((a > BOUND_MS / 1e3).mean())))


def test_trial_columns_are_the_intervals_frames(session: Path) -> None:
    trials = pd.read_parquet(session / "trials.parquet").set_index("trial")
    frames = pd.read_parquet(session / "frames.parquet")
    meta = json.loads((session / "session.json").read_text())
    assert not frames["gaze_valid"].all()  # blinks: held frames are left out
    want = _expected(frames, meta)
    got = trials.loc[want.index, list(want.columns)]
    assert np.allclose(got.to_numpy(dtype=float), want.to_numpy(dtype=float), rtol=0, atol=1e-12)
    assert ((want["gaze_age_median_s"] > 0.010) & (want["gaze_age_max_s"] < 0.010 + 1 / 120 + 1 / 90)).all()
    assert (want["gaze_age_over_share"].between(0.2, 0.8)).all()
    assert (trials["gaze_age_ok"] == False).all()  # noqa: E712 (over 5 % of the frames)
    # session.json: the bound, the session's summary by phase kind, the trials over it
    assert meta["gaze_latency"]["max_gaze_age_ms"] == BOUND_MS
    summary = meta["summary"]["gaze_age"]
    assert set(summary["by_kind"]) == {"cross", "stimulus", "blank"}  # the simulated observer answers at once
    valid = frames[frames["gaze_valid"]]["gaze_age_at_display_s"]
    assert summary["n_frames"] == len(valid) and summary["median_s"] == pytest.approx(float(valid.median()), abs=1e-12)
    assert summary["trials_over"] == sorted(trials.index.tolist()) == meta["integrity"]["late_gaze_trials"]
    assert meta["integrity"]["max_gaze_age_ms"] == BOUND_MS


def test_timing_report_and_figure(session: Path, tmp_path: Path) -> None:
    from psyop.figures.timing_figures import timing_figure
    from psyop.session.timing import session_report

    meta = json.loads((session / "session.json").read_text())
    report = session_report(str(session), meta, pd.read_parquet(session / "trials.parquet"),
                            pd.read_parquet(session / "frames.parquet"))
    lines = "\n".join(report.lines())
    assert "gaze-to-photon age (display time - gaze sample time" in lines
    assert f"bound {BOUND_MS:g} ms (intrinsic, interval frames)" in lines and "2 trials over 5%" in lines
    assert "  stimulus: " in lines
    written = timing_figure(report, tmp_path / "t.png")
    assert written and written[0].is_file()


def test_the_analysis_counts_late_trials_like_low_gaze_ones(session: Path) -> None:
    from psyop.quality.latency import latency_sentence
    from psyop.statistics.dataset import LateGazeWarning, load_dataset

    root = session.parents[2]
    with pytest.warns(LateGazeWarning, match="2 of 2 trials had more frames with gaze older"):
        kept = load_dataset(root, "age").trials
    assert kept.attrs["n_late_gaze"] == 2 and kept.attrs["n_late_gaze_dropped"] == 0 and len(kept) == 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LateGazeWarning)
        dropped = load_dataset(root, "age", drop_late_gaze=True).trials
    assert len(dropped) == 0 and dropped.attrs["n_late_gaze_dropped"] == 2
    sentence = latency_sentence([session])
    assert sentence.startswith("Gaze-to-photon latency") and "95th percentile" in sentence
    assert f"2 of 2 trials had more than 5% of their interval frames over the protocol's bound of {BOUND_MS:g} ms" \
        in sentence


def test_trial_columns_rule() -> None:
    ages = np.array([0.010, 0.012, 0.020, np.nan])
    rule = GazeLatency(max_age_s=0.015, max_over_share=0.5)
    out = trial_columns(ages, ages, rule)
    assert out["gaze_age_median_s"] == pytest.approx(0.012) and out["gaze_age_max_s"] == 0.020
    assert out["gaze_age_over_share"] == pytest.approx(1 / 3) and out["gaze_age_ok"] is True
    assert trial_columns(ages, ages, GazeLatency(max_age_s=0.011, max_over_share=0.5))["gaze_age_ok"] is False
    unbounded = trial_columns(ages, ages, GazeLatency())
    assert unbounded["gaze_age_over_share"] is None and unbounded["gaze_age_ok"] is None
    assert trial_columns(np.array([np.nan]), np.array([np.nan]), rule) == dict.fromkeys(GAZE_AGE_COLUMNS)
