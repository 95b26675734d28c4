"""The quality: rules (issue 27 item 3): validated, applied at analysis time, and they exclude exactly the
participants simulated to fail them (observer eye overrides per participant)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from psyop.protocol import load_protocol
from psyop.protocol.quality import QUALITY_MEASURES
from psyop.quality.measures import TRIAL_MEASURES
from psyop.quality.rules import apply_rules, included_mask, methods_sentence
from psyop.quality.session import measure_session
from psyop.schedule import compile_schedule
from psyop.run.runner import SessionOptions, run_session
from tests.session.session_helpers import small_protocol

QUALITY = """quality:
  trials:
    - {measure: data_loss_share, max: 0.5, reason: the eye tracker lost the pupil}
  participants:
    - {measure: pursuit_gain, min: 0.6, reason: failing to follow instructions}
  min_included_trials: 3
  min_included_trials_reason: the eye tracker failing to track their pupils
"""
EYE = ("    raw_stream: every_sample\n    participants:\n"
       "      LOST: {nan_burst_rate_hz: 30}\n      LAZY: {pursuit_gain: 0.3}\n")


def _protocol(directory: Path, quality: str) -> Path:
    path = small_protocol(directory, "detection", 1)
    text = re.sub(r"(?m)^    raw_stream: \S+.*\n", EYE, path.read_text())
    path.write_text(text + quality)
    return path


def test_rule_measures_are_the_measures_psyop_computes() -> None:
    assert QUALITY_MEASURES == tuple(TRIAL_MEASURES)


def test_unknown_measure_is_refused_with_the_list_file_line_exit_2(tmp_path: Path) -> None:
    path = _protocol(tmp_path, QUALITY.replace("pursuit_gain", "pursuit_glee"))
    done = subprocess.run([sys.executable, "-m", "psyop", "validate", str(path)], capture_output=True, text=True, check=False)
    assert done.returncode == 2, done.stderr
    assert "pursuit_glee" in done.stderr and "data_loss_share, longest_gap_s" in done.stderr
    assert re.search(rf"{re.escape(path.name)}:\d+", done.stderr) and "Traceback" not in done.stderr


@pytest.fixture(scope="module")
def measured(tmp_path_factory: pytest.TempPathFactory) -> tuple[pd.DataFrame, object]:
    directory = tmp_path_factory.mktemp("rules")
    protocol = load_protocol(_protocol(directory, QUALITY))
    tables = []
    for seed, who in enumerate(("OK1", "LOST", "LAZY", "OK2")):
        options = SessionOptions(participant=who, seed=seed, data_root=directory / "data", progress=False,
                                 render="cameras")
        assert run_session(protocol, compile_schedule, options).status == "complete"
        tables.append(measure_session(directory / "data" / "detection" / f"sub-{who}" / "ses-1")[0])
    return pd.concat(tables, ignore_index=True), protocol, directory / "data"


def test_rules_exclude_exactly_the_participants_simulated_to_fail(measured) -> None:
    measures, protocol, _ = measured
    exclusions = apply_rules(measures, protocol.quality)
    people = exclusions[exclusions["level"] == "participant"]
    assert set(people["participant"]) == {"LOST", "LAZY"}
    assert set(people.loc[people["participant"] == "LAZY", "rule"]) == {"median pursuit_gain < 0.6"}
    assert "included trials < 3" in set(people.loc[people["participant"] == "LOST", "rule"])
    kept = included_mask(measures, exclusions)
    assert set(measures.loc[kept, "participant"]) == {"OK1", "OK2"}
    sentence = methods_sentence(exclusions, measures["participant"].nunique(), len(measures))
    assert sentence.startswith("Of 4 participants, 2 were excluded") and "failing to follow instructions" in sentence


def test_the_study_analysis_loads_only_the_included_data_and_says_so(measured) -> None:
    from psyop.statistics.dataset import load_dataset

    trials = load_dataset(measured[2], "detection").trials
    assert set(trials["participant"]) == {"OK1", "OK2"}
    assert trials.attrs["quality"].startswith("Of 4 participants, 2 were excluded")
    assert trials.attrs["n_quality_excluded"] > 0


def test_no_quality_section_excludes_nothing(measured) -> None:
    measures = measured[0]
    assert apply_rules(measures, None).empty
    assert included_mask(measures, apply_rules(measures, None)).all()


def test_a_requested_stream_is_measured_from_its_requested_samples_only(tmp_path: Path) -> None:
    from psyop.quality.session import NEEDS_EVERY_SAMPLE

    protocol = load_protocol(small_protocol(tmp_path, "detection", 1))  # shipped: raw_stream: requested
    options = SessionOptions(participant="Q", seed=1, data_root=tmp_path / "data", progress=False, render="cameras")
    assert run_session(protocol, compile_schedule, options).status == "complete"
    ses = tmp_path / "data" / "detection" / "sub-Q" / "ses-1"
    meta = json.loads((ses / "session.json").read_text())
    meta["sim_tracker_faults"] = None  # not rebuilt from the seed (tests/quality/test_resimulate.py): as recorded
    (ses / "session.json").write_text(json.dumps(meta))
    measures = measure_session(ses)[0]
    gaze = pd.read_parquet(ses / "gaze.parquet")
    assert set(measures["raw_stream"]) == {"requested"}
    assert measures[list(NEEDS_EVERY_SAMPLE)].isna().all().all()
    assert measures["n_samples_expected"].sum() == len(gaze)  # loss over the samples it asked for, not 120 Hz
    assert measures["data_loss_share"].dropna().between(0, 1).all()
    assert measures.loc[measures["n_samples_expected"] == 0, "data_loss_share"].isna().all()
