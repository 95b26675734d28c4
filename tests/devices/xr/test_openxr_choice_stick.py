"""One of several options picked with the controllers on a real OpenXR runtime (Monado's remote driver emulates
Valve Index controllers; ``--responses openxr``): a 4-location n_afc's alternative and a questionnaire item's scale
point, each moved with the right stick's sideways flicks from its start (the middle: alternative 2 of 4, point 1 of
0..2) and confirmed with the trigger (psyop.session.scale_picker, psyop.session.rating_stick, psyop.session.screens).
The logged answers are the ones the injected flicks lead to; the n_afc's ``choice_path`` holds the start and each
flick. The participant starts CHOOSE_AFTER_S after the session's folder appears (the log opens once the runtime is
focused and a controller is active, before the first screen), never at a fixed time from the start."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pandas as pd
from monado import RemoteState, run_driven

HEAD = """
psyop_protocol: 1
study: {name: xr_choice, title: where was the red disc}
display: {profile: vive_pro, eye_model: gullstrand_emsley_relaxed, ipd: tracker}
eyes: stereo
scene:
  - id: target
    kind: disc
    size_deg: 3
    depth: {factor: level_D}
    centre_deg: [{factor: target_azimuth_deg}, {factor: target_elevation_deg}]
    surface: {kind: solid, rgb: [1, 0, 0]}
design:
  factors:
    level_D: {levels: [1.0]}
  repetitions: 1
  randomisation: {kind: full}
response:
  kind: n_afc
  n: 4
  alternatives: locations
  locations_deg: [[-8, 0], [0, 8], [8, 0], [0, -8]]
  target: {mode: conventional}
"""
#: the 4-AFC: one trial answered with the stick (the remote driver's 320x240 px views fit a short prompt: the help
#: line a default prompt adds is left out)
FOUR_AFC = HEAD + """trial:
  phases:
    - {kind: interval, duration_s: 0.2}
    - {kind: response, expected_s: 2, timeout_s: 60, prompt: Where?}
"""
#: a two-item questionnaire before the one trial, whose response times out (only the items are answered)
QUESTIONNAIRE = HEAD + """trial:
  phases:
    - {kind: interval, duration_s: 0.2}
    - {kind: response, expected_s: 0.5, timeout_s: 0.5, prompt: Where?}
session:
  questionnaires:
    - name: comfort
      when: [start]
      items: [Eyes, Head]
      scale: {points: 3, labels: [a, b, c]}
"""
CHOOSE_AFTER_S = 3.0
#: from CHOOSE_AFTER_S: (start, end, stick x) of each flick (full deflection, then rest) and (start, end) of each
#: confirming trigger press, each held long enough that a slow frame loop (llvmpipe on a loaded machine) still syncs
#: the runtime's input while it is held
AFC_FLICKS = ((2.0, 3.0, 1.0), (4.0, 5.0, 1.0))
AFC_CONFIRMS = ((6.5, 7.5),)
ITEM_FLICKS = ((1.0, 1.8, -1.0), (4.2, 5.0, 1.0))  # item 1: one left; item 2: one right
ITEM_CONFIRMS = ((2.6, 3.4), (5.8, 6.6))


def _run(tmp_path: Path, text: str, flicks: tuple[tuple[float, float, float], ...],
         confirms: tuple[tuple[float, float], ...]) -> Path:
    """``psyop run`` on the remote driver with the right stick and trigger driven as ``flicks`` and ``confirms``
    say; the session's folder."""
    protocol = tmp_path / "xr_choice.yaml"
    protocol.write_text(text)
    cmd = [sys.executable, "-m", "psyop", "run", str(protocol), "--participant", "H1", "--data",
           str(tmp_path / "data"), "--display", "openxr", "--responses", "openxr", "--clock", "real", "--no-progress"]
    session = tmp_path / "data" / "xr_choice" / "sub-H1" / "ses-1"
    opened: list[float] = []

    def drive(state: RemoteState, elapsed_s: float) -> None:
        if not opened and session.is_dir():
            opened.append(elapsed_s)
        t = elapsed_s - opened[0] - CHOOSE_AFTER_S if opened else -100.0
        state.right_thumbstick_x = next((x for a, b, x in flicks if a <= t < b), 0.0)
        state.right_trigger = any(a <= t < b for a, b in confirms)

    done = run_driven(cmd, tmp_path, RemoteState(), drive)
    assert done.returncode == 0, done.stderr[-3000:]
    return session


def test_a_location_of_four_is_picked_with_the_stick_and_confirmed_with_the_trigger(tmp_path: Path) -> None:
    session = _run(tmp_path, FOUR_AFC, AFC_FLICKS, AFC_CONFIRMS)
    trials = pd.read_parquet(session / "trials.parquet")
    assert len(trials) == 1
    row = trials.iloc[0]
    assert row["response"] == "4", (row["response"], row["choice_path"])  # alternative 2 + two right flicks
    assert bool(row["correct"]) == (int(row["correct_location"]) == 4)
    path = json.loads(row["choice_path"])
    assert [point for _, point in path] == [2, 3, 4], path
    (t0, _), (t1, _), (t2, _) = path
    answer_s = float(row["response_time_s"])
    assert t0 == 0.0 and 0.0 < t1 < t2 < answer_s, (path, answer_s)
    # as far apart as the flicks and the trigger were (to half a second: the runtime's input syncs once a frame)
    assert abs((t2 - t1) - (AFC_FLICKS[1][0] - AFC_FLICKS[0][0])) < 0.5, path
    assert abs((answer_s - t2) - (AFC_CONFIRMS[0][0] - AFC_FLICKS[1][0])) < 0.5, (path, answer_s)


def test_questionnaire_items_are_answered_with_the_stick_and_the_trigger(tmp_path: Path) -> None:
    session = _run(tmp_path, QUESTIONNAIRE, ITEM_FLICKS, ITEM_CONFIRMS)
    answers = pd.read_parquet(session / "questionnaires.parquet").sort_values("item")
    # each starts at point 1 of 0..2 (the middle); item 1 one left, item 2 one right
    assert answers["answer"].tolist() == [0, 2], answers[["item", "answer", "answered_by"]]
    assert answers["answered_by"].tolist() == ["controllers:0", "controllers:2"]
    assert answers["answer_label"].tolist() == ["a", "c"]
    (end_1, start_2) = float(answers["end_s"].iloc[0]), float(answers["start_s"].iloc[1])
    # item 2 ends with the second trigger press, as long after the first as they were apart (to half a second)
    gap_s = float(answers["end_s"].iloc[1]) - end_1
    assert start_2 >= end_1 and abs(gap_s - (ITEM_CONFIRMS[1][0] - ITEM_CONFIRMS[0][0])) < 0.5, answers[["start_s", "end_s"]]
    trials = pd.read_parquet(session / "trials.parquet")
    assert len(trials) == 1  # the trial after the items ran (its response timed out)
