"""Gaze validation in the headset (issue 27 item 7): the ``gaze_validation:`` section shows its points,
measures accuracy and precision on each, re-runs or stops the session as ``require`` says, and its numbers
reach validation.parquet, ``psyop gaze``, the quality rules and the BIDS sidecars. A simulated eye with a known
tracker offset and noise gives known accuracy and precision (the recovery test)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from psyop.errors import UserError
from psyop.finalised import verify_session
from psyop.optics.angles import fick_angles_deg
from psyop.protocol import load_protocol, parse_protocol
from psyop.quality.rules import apply_rules
from psyop.quality.session import measure_session
from psyop.session.plan import compile_plan
from psyop.session.scene_renderer import SceneRenderer
from psyop.run.simulate import plan_jobs, run_job
from psyop.session.validation import _precision_deg, validation_phase

REPO = Path(__file__).resolve().parents[2]
ORDINAL = (REPO / "protocols" / "ordinal.yaml").read_text()

#: the simulated tracker's error is a constant drift of 1 deg (no per-target offset, no growth with
#: eccentricity), its noise 0.1 deg per axis: each point's mean error is sqrt(1 + 2 * 0.1^2) ~ 1.01 deg,
#: the radial SD sqrt(2) * 0.1 and the RMS sample-to-sample 2 * 0.1 (independent samples)
KNOWN_EYE = """    error_centre_deg: 0
    error_per_15deg: 0
    drift_start_deg: 1.0
    drift_deg_per_min: 0
    precision_deg: 0.1
    blink_rate_hz: 0
"""


def _protocol(tmp_path: Path, validation: str, *, eye: str = KNOWN_EYE, name: str = "ordval",
              design: tuple[str, str] | None = None, extra: str = "") -> Path:
    text = ORDINAL.replace("repetitions: 15 ", "repetitions: 1 ").replace("name: ordinal", f"name: {name}")
    text = text.replace("    raw_stream: requested ", eye + "    raw_stream: requested ")
    if design is not None:
        text = text.replace(*design)
    path = tmp_path / f"{name}.yaml"
    path.write_text(text + "\n" + validation + extra)
    return path


def _run(path: Path, data: Path, participant: str = "S01") -> tuple[str, Path]:
    study = load_protocol(path).study.name
    job = next(j for j in plan_jobs([path], 2020, {study: 6}) if j.participant == participant)
    status = run_job(job, data)[2]
    return status, data / study / f"sub-{participant}" / "ses-1"


def test_recovers_the_simulated_accuracy_and_precision(tmp_path: Path) -> None:
    path = _protocol(tmp_path, "gaze_validation:\n  when: [start, end]\n")
    status, session = _run(path, tmp_path / "data")
    assert status == "complete"
    verify_session(session)  # validation.parquet is finalised and checksummed with the other files
    assert "validation.parquet" in json.loads((session / "session.json").read_text())["finalised_files"]
    table = pd.read_parquet(session / "validation.parquet")
    points, overall = table[table["point"] >= 0], table[table["point"] == -1]
    assert list(overall["when"]) == ["start", "end"] and len(points) == 18  # the default 9 points, twice
    assert sorted(map(tuple, points[["target_az_deg", "target_el_deg"]].drop_duplicates().to_numpy())) == \
        sorted((a, e) for a in (-15.0, 0.0, 15.0) for e in (-15.0, 0.0, 15.0))
    expected_error = math.sqrt(1.0 + 2 * 0.1 ** 2)
    assert np.all(np.abs(points["mean_error_deg"] - expected_error) < 0.08)  # per point: about 80 samples
    assert np.all(np.abs(overall["mean_error_deg"] - expected_error) < 0.03)
    assert np.all(np.abs(overall["precision_sd_deg"] / (math.sqrt(2) * 0.1) - 1) < 0.1)
    assert np.all(np.abs(overall["precision_rms_s2s_deg"] / (2 * 0.1) - 1) < 0.1)
    assert np.all(points["n_valid"] >= 0.9 * 90)  # one poll per 90 Hz frame over the 1 s dwell
    assert overall["passed"].all()
    # the trials get the validation that preceded them; psyop gaze's table carries it
    measures, _ = measure_session(session)
    first = float(overall["mean_error_deg"].iloc[0])
    assert np.allclose(measures["validation_mean_error_deg"], first)
    from psyop.quality.included import study_quality

    sentence = study_quality([session], None).sentence  # results/<study>_quality.txt's methods sentence
    assert "Gaze validation (9 points, 2 validations in 1 sessions): mean accuracy 1.0" in sentence


def test_precision_is_pymovements_rms_s2s_and_std_rms() -> None:
    import polars as pl
    from pymovements.measure.samples import rms_s2s, std_rms

    rng = np.random.default_rng(3)
    az, el = rng.normal(0, 0.2, 200) + 5, rng.normal(0, 0.1, 200) - 2
    out = pl.DataFrame({"position": np.stack([az, el], axis=1).tolist()}).select(rms_s2s(column="position"),
                                                                                 std_rms(column="position"))
    rms, sd = _precision_deg(az, el)
    assert rms == pytest.approx(float(out["rms_s2s"][0]), rel=1e-12)
    assert sd == pytest.approx(float(out["std_rms"][0]), rel=1e-12)


def _attempt_errors(tmp_path: Path, eye: str, participant: str) -> list[float]:
    """The mean errors of three attempts that all fail (a bound no tracker meets; the same study and
    participant, so the same seed, as the session that uses them)."""
    (tmp_path / "probe").mkdir()
    path = _protocol(tmp_path / "probe", "gaze_validation:\n  when: [start]\n  require: {max_mean_error_deg: 0.001, "
                     "max_attempts: 3}\n", eye=eye)
    status, session = _run(path, tmp_path / "probe", participant)
    assert status == "validation_failed"
    table = pd.read_parquet(session / "validation.parquet")
    return list(table.loc[table["point"] == -1, "mean_error_deg"])


#: a tracker whose error is a random offset per target: each attempt's error differs
RANDOM_EYE = "    error_centre_deg: 1.5\n    drift_start_deg: 0\n"
PARTICIPANT = "S04"  # its seed's first attempt is worse than a later one (the test says so if not)


def test_an_attempt_over_the_bound_is_run_again_and_the_next_one_lets_trials_go_on(tmp_path: Path) -> None:
    errors = _attempt_errors(tmp_path, RANDOM_EYE, PARTICIPANT)
    better = [k for k in (1, 2) if errors[k] < errors[0]]
    assert better, f"the seed gives no attempt better than the first: {errors}; pick another PARTICIPANT"
    bound = (errors[0] + errors[better[0]]) / 2  # the first fails, a later one passes
    path = _protocol(tmp_path, f"gaze_validation:\n  when: [start]\n  require: {{max_mean_error_deg: {bound:.6f}, "
                     "max_attempts: 3}\n", eye=RANDOM_EYE)
    status, session = _run(path, tmp_path / "data", PARTICIPANT)
    assert status == "complete"
    overall = pd.read_parquet(session / "validation.parquet").query("point == -1")
    assert list(overall["passed"]) == [False] * better[0] + [True]
    assert list(overall["mean_error_deg"]) == pytest.approx(errors[:better[0] + 1])
    assert len(pd.read_parquet(session / "trials.parquet")) == 6
    from psyop.quality.included import validation_bounded
    from psyop.quality.validation import validation_sentence
    assert validation_bounded([session])
    assert "0 of 1 validations met the protocol's bound at the first attempt." in validation_sentence([session], True)


def test_without_a_bound_the_methods_sentence_counts_no_passes(tmp_path: Path) -> None:
    from psyop.quality.included import validation_bounded
    from psyop.quality.validation import validation_sentence

    path = _protocol(tmp_path, "gaze_validation:\n  when: [start]\n  points_deg: [[0, 0]]\n")
    status, session = _run(path, tmp_path / "data")
    assert status == "complete"
    assert not validation_bounded([session])
    sentence = validation_sentence([session], False)
    assert "states no bound (gaze_validation.require)" in sentence and "met the protocol's bound" not in sentence


def test_the_stop_rule_ends_the_session_with_one_line_exit_3_and_loses_nothing(tmp_path: Path, capsys) -> None:
    from psyop.cli import main as cli_main

    path = _protocol(tmp_path, "gaze_validation:\n  when: [start]\n  require: {max_mean_error_deg: 0.5, "
                     "max_attempts: 2}\n")
    code = cli_main(["run", str(path), "--participant", "S01", "--tracker", "sim", "--responses", "sim", "--clock",
                     "virtual", "--data", str(tmp_path / "data"), "--no-progress"])
    assert code == 3
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and err[0].startswith("psyop run: validation_failed: gaze validation (start) failed 2 of 2")
    assert "Traceback" not in err[0]
    session = tmp_path / "data" / "ordval" / "sub-S01" / "ses-1"
    verify_session(session)
    meta = json.loads((session / "session.json").read_text())
    assert meta["status"] == "incomplete" and meta["summary"]["outcome"] == "validation_failed"
    table = pd.read_parquet(session / "validation.parquet")
    assert list(table.loc[table["point"] == -1, "attempt"]) == [1, 2]
    gaze = pd.read_parquet(session / "gaze.parquet")
    capsys.readouterr()
    assert cli_main(["gaze", str(session)]) == 0  # psyop gaze reads a session stopped before its first trial
    printed = capsys.readouterr().out
    assert printed.count("FAILED the protocol's gaze_validation.require") == 2
    own = gaze[gaze["trial"] == -1]["gaze_sample_t_s"]
    for _, point in table[table["point"] >= 0].iterrows():  # every sample measured is in the raw stream
        # measured: the samples delivered by the attempt's end; the last one or two (the tracker's latency) arrive
        # with the next attempt's, still in the raw stream
        assert 0 <= ((own >= point["start_s"]) & (own < point["end_s"])).sum() - point["n_samples"] <= 2


def test_between_blocks_runs_at_each_change_of_block(tmp_path: Path) -> None:
    path = _protocol(tmp_path, "gaze_validation:\n  when: [between_blocks]\n  points_deg: [[0, 0], [10, 0]]\n"
                     "  dwell_s: 0.5\n  settle_s: 0.2\n",
                     design=("randomisation: {kind: full}", "randomisation: {kind: blocked, by: [mode]}"))
    status, session = _run(path, tmp_path / "data")
    assert status == "complete"
    trials = pd.read_parquet(session / "trials.parquet").sort_values("trial_start_s")
    starts = trials.loc[trials["block"].diff().fillna(0) != 0, "trial"].astype(int).tolist()
    overall = pd.read_parquet(session / "validation.parquet").query("point == -1")
    assert len(starts) == 2 and list(overall["before_trial"]) == starts
    assert set(overall["when"]) == {"between_blocks"}


def test_a_rule_on_validation_error_excludes_exactly_the_participant_simulated_to_fail_it(tmp_path: Path) -> None:
    eye = KNOWN_EYE + "    participants:\n      S02: {drift_start_deg: 3.0}\n"
    quality = ("quality:\n  participants:\n    - {measure: validation_mean_error_deg, max: 2.0, "
               "reason: tracker validation error over 2 deg}\n")
    text = _protocol(tmp_path, "gaze_validation:\n  when: [start]\n", eye=eye, extra=quality)
    measures = pd.concat([measure_session(_run(text, tmp_path / "data", p)[1])[0] for p in ("S01", "S02")])
    exclusions = apply_rules(measures, load_protocol(text).quality)
    assert list(exclusions["participant"]) == ["S02"] and list(exclusions["level"]) == ["participant"]


def test_the_rendered_frame_shows_the_target_where_the_point_is() -> None:
    """The validation target is drawn at its Fick angles from the head origin: the disc's white pixels are
    centred on the pixel the exact projection of its centre gives, its black centre on top."""
    plan = compile_plan(load_protocol(REPO / "protocols" / "ordinal.yaml"), tracker_ipd_m=0.064)
    from psyop.protocol.validation import GazeValidation

    validation = GazeValidation(when=["start"], points_deg=[(10.0, -5.0)], target_size_deg=2.0, distance_m=1.0)
    phase = validation_phase(validation, 0)
    renderer = SceneRenderer(plan, scale=0.5)
    try:
        check = renderer.render({"trial": -1}, phase, "conventional", 0.1, (0.0, 0.0, -1.0))
        assert check.checked and check.ok
        eye = renderer.last_eye
        img = renderer._renderer.image(eye)
        camera = renderer._camera(eye, (0.0, 0.0, -1.0), "conventional", None)
    finally:
        renderer.close()
    from psyop.optics.angles import fick_direction

    centre = np.append(1.0 * fick_direction(10.0, -5.0), 1.0)
    clip = camera.projection @ camera.view @ centre
    h, w, _ = img.shape
    x_px, y_px = (clip[0] / clip[3] + 1) / 2 * w, (1 - clip[1] / clip[3]) / 2 * h
    white = np.all(img > 0.75, axis=2)
    ys, xs = np.nonzero(white)
    assert white.sum() > 20
    assert abs(xs.mean() + 0.5 - x_px) < 1.0 and abs(ys.mean() + 0.5 - y_px) < 1.0
    dark = np.all(img < 0.2, axis=2)
    dys, dxs = np.nonzero(dark)
    assert dark.sum() > 0 and abs(dxs.mean() + 0.5 - x_px) < 1.0 and abs(dys.mean() + 0.5 - y_px) < 1.0
    assert np.allclose(img[0, 0], 0.5, atol=0.02)  # background elsewhere
    az, el = fick_angles_deg(fick_direction(10.0, -5.0))
    assert (float(az), float(el)) == pytest.approx((10.0, -5.0))


def test_a_point_outside_the_displays_field_of_view_is_refused_at_its_line() -> None:
    narrow = ORDINAL.replace("profile: vive_pro ",
                             "profile: {name: narrow, width_px: 400, height_px: 400, refresh_hz: 90, "
                             "horizontal_fov_deg: 30, vertical_fov_deg: 30} ")
    assert narrow != ORDINAL
    ok = narrow + "\ngaze_validation:\n  when: [start]\n  points_deg: [[0, 0], [10, 0], [0, -12]]\n"
    parse_protocol(ok, "study.yaml")  # inside +-15 deg, less the disc and the eye's offset: shown
    with pytest.raises(UserError) as info:
        parse_protocol(narrow + "\ngaze_validation:\n  when: [start]\n  points_deg: [[0, 0], [20, 0]]\n",
                       "study.yaml")
    message = str(info.value)
    assert "points_deg[1]" in message and "[20, 0]" in message and "never see it" in message, message
    with pytest.raises(UserError) as info:  # the default 9 points reach +-15 deg: not wholly inside +-15
        parse_protocol(narrow + "\ngaze_validation:\n  when: [start]\n", "study.yaml")
    assert "never see it" in str(info.value)


@pytest.mark.parametrize(("block", "needle", "words"), [
    ("gaze_validation:\n  when: [between_blocks]\n", "between_blocks", "needs blocks"),
    ("gaze_validation:\n  when: [start]\n  points_deg: [[0, 0], [50, 0]]\n", "points_deg", "outside +-40"),
    ("gaze_validation:\n  when: [start, start]\n", "when:", "at most once"),
    ("gaze_validation:\n  when: [start]\n  require: {max_mean_error_deg: 0}\n", "require", "greater than 0"),
    ("gaze_validation:\n  when: [start]\n  dwel_s: 1\n", "dwel_s", "dwel_s"),
    ("quality:\n  trials:\n    - {measure: validation_max_error_deg, max: 3}\n", "validation_max_error_deg",
     "needs a gaze_validation: section"),
])
def test_a_bad_section_is_one_error_at_its_line(tmp_path: Path, block: str, needle: str, words: str) -> None:
    text = ORDINAL + "\n" + block
    with pytest.raises(UserError) as info:
        parse_protocol(text, "study.yaml")
    line = next(i for i, row in enumerate(text.splitlines(), 1) if needle in row and not row.startswith("#"))
    message = str(info.value)
    assert f"study.yaml:{line}" in message and words in message, message


def test_per_eye_accuracy_where_the_tracker_gives_both_eyes() -> None:
    """Each eye's error is the angle between its gaze normal and the line from its centre to the target:
    normals aimed exactly at a target 1 m ahead, one of them turned 2 deg, give 0 and 2 deg."""
    from psyop.optics.angles import fick_direction
    from psyop.session.validation import point_measures

    n = 20
    target_m = fick_direction(10.0, 5.0)
    rows = {"gaze_sample_t_s": np.linspace(0.0, 0.95, n), "gaze_valid": np.ones(n, dtype=bool)}
    for axis, value in zip("xyz", target_m):
        rows[f"fixation_{axis}_m"] = np.full(n, value)
    for eye, x_m, turn_deg in (("left", -0.032, 0.0), ("right", 0.032, 2.0)):
        to_target = target_m - np.array([x_m, 0.0, 0.0])
        az, el = fick_angles_deg(to_target)
        normal = fick_direction(float(az) + turn_deg, float(el))
        for i, axis in enumerate("xyz"):
            rows[f"eye_centre_{eye}_{axis}_m"] = np.full(n, [x_m, 0.0, 0.0][i])
            rows[f"gaze_normal_{eye}_{axis}"] = np.full(n, normal[i])
    out = point_measures(pd.DataFrame(rows), 0.0, 1.0, (10.0, 5.0), 1.0)
    assert out["n_valid"] == n and out["mean_error_deg"] == pytest.approx(0.0, abs=1e-6)
    assert out["left_mean_error_deg"] == pytest.approx(0.0, abs=1e-6)
    assert out["right_mean_error_deg"] == pytest.approx(2.0 * math.cos(math.radians(float(el))), rel=1e-3)


def test_every_frame_the_display_paces_the_targets_and_gaze_is_asked_for_each_frame(tmp_path: Path) -> None:
    """A watched session (every frame through the display and the renderer, here cameras only) validates the
    same way: one gaze request per display frame, the frames counted by the display."""
    from psyop.schedule import compile_schedule
    from psyop.run.runner import SessionOptions, run_session

    path = _protocol(tmp_path, "gaze_validation:\n  when: [start]\n  points_deg: [[0, 0], [-10, 10]]\n")
    options = SessionOptions(participant="S01", seed=5, data_root=tmp_path / "data", progress=False,
                             every_frame=True, render="cameras")
    assert run_session(load_protocol(path), compile_schedule, options).status == "complete"
    session = tmp_path / "data" / "ordval" / "sub-S01" / "ses-1"
    table = pd.read_parquet(session / "validation.parquet")
    points = table[table["point"] >= 0]
    assert len(points) == 2 and np.all(points["n_samples"] >= 88)  # 90 Hz frames over the 1 s dwell
    assert np.all(np.abs(points["mean_error_deg"] - math.sqrt(1.0 + 2 * 0.1 ** 2)) < 0.08)
    meta = json.loads((session / "session.json").read_text())
    assert meta["summary"]["display"]["frames"] >= 2 * 1.5 * 90 - 2  # the validation's frames went to the display


def test_the_end_validation_runs_once_and_records_a_miss_without_stopping(tmp_path: Path) -> None:
    path = _protocol(tmp_path, "gaze_validation:\n  when: [end]\n  points_deg: [[0, 0]]\n"
                     "  require: {max_mean_error_deg: 0.5, max_attempts: 3}\n")
    status, session = _run(path, tmp_path / "data")
    assert status == "complete"
    overall = pd.read_parquet(session / "validation.parquet").query("point == -1")
    assert list(overall["attempt"]) == [1] and list(overall["passed"]) == [False]
    measures, _ = measure_session(session)  # trials before the only validation get it (the first after them)
    assert np.allclose(measures["validation_mean_error_deg"], float(overall["mean_error_deg"].iloc[0]))


class _Log:
    keeps_samples = False
    run_index = 0


@dataclass
class _Host:
    """The parts of the trial loop a validation uses (psyop.session.validation.ValidationHost)."""

    clock: object
    gaze: object
    events: tuple
    renderer: None = None
    display: object = field(default_factory=lambda: type("Ready", (), {"wait_until_ready": lambda self: None})())
    store: _Log = field(default_factory=_Log)
    config: object = field(default_factory=lambda: type("Regime", (), {"every_frame": False})())
    frame_period_s: float = 1 / 90


class _Sink:
    def __init__(self) -> None:
        self.events: list = []

    def emit(self, event) -> None:  # type: ignore[no-untyped-def]
        self.events.append(event)

    def close(self) -> None:
        return None


def test_each_target_onset_is_a_phase_event_for_outside_recorders() -> None:
    from psyop.protocol.validation import GazeValidation
    from psyop.session.clock import VirtualClock
    from psyop.session.gaze.simulated import SimulatedTracker
    from psyop.session.validation import GazeValidator

    sink = _Sink()
    host = _Host(clock=VirtualClock(), gaze=SimulatedTracker(7), events=(sink,))
    validation = GazeValidation(when=["start"], points_deg=[(0.0, 0.0), (5.0, 5.0), (-5.0, 0.0)], settle_s=0.2,
                                dwell_s=0.5)
    rows = GazeValidator(validation).run("start", host, 0)  # type: ignore[arg-type]
    assert [(e.kind, e.trial, e.condition, e.value) for e in sink.events] == [
        ("phase", -1, "gaze_validation", f"validation_{i}") for i in range(3)]
    assert [e.t_s for e in sink.events] == pytest.approx([0.0, 0.7, 1.4])
    assert list(rows["point"]) == [0, 1, 2, -1] and rows["n_valid"].iloc[:3].min() >= 40


def test_a_stop_between_blocks_keeps_the_recorded_trials_and_rerunning_resumes(tmp_path: Path) -> None:
    """Three blocks; a bound no tracker meets stops the session at each change of block. Each rerun of the
    same command resumes after the last recorded trial (a resumed run's first trial has no block before it
    in that run, so it is not held back), until every trial is recorded."""
    from psyop.cli import main as cli_main

    path = _protocol(tmp_path, "gaze_validation:\n  when: [between_blocks]\n  points_deg: [[0, 0]]\n"
                     "  require: {max_mean_error_deg: 0.001, max_attempts: 1}\n",
                     design=("randomisation: {kind: full}", "randomisation: {kind: blocked, by: [mode]}"))
    command = ["run", str(path), "--participant", "S01", "--tracker", "sim", "--responses", "sim", "--clock",
               "virtual", "--data", str(tmp_path / "data"), "--no-progress"]
    session = tmp_path / "data" / "ordval" / "sub-S01" / "ses-1"
    recorded = []
    for _ in range(2):
        assert cli_main(command) == 3
        verify_session(session)
        recorded.append(len(pd.read_parquet(session / "trials.parquet")))
    assert cli_main(command) == 0
    trials = pd.read_parquet(session / "trials.parquet")
    assert recorded == [2, 4] and len(trials) == 6  # 2 trials per block: nothing recorded was lost
    assert json.loads((session / "session.json").read_text())["status"] == "complete"
    overall = pd.read_parquet(session / "validation.parquet").query("point == -1")
    assert list(overall["run"]) == [0, 1] and not overall["passed"].any()
