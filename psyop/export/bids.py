"""``psyop export --bids DIR``: a data root's sessions as a BIDS dataset (behaviour + eye tracking).

Layout (one BIDS run per psyop run of a session, task = the study name without ``_``/``-``)::

    DIR/dataset_description.json, README.md, participants.tsv/.json
    DIR/sub-<ID>/ses-<N>/beh/sub-<ID>_ses-<N>_task-<study>_run-<R>_events.tsv/.json
    DIR/sub-<ID>/ses-<N>/beh/..._recording-eye<K>_physio.tsv.gz/.json        (BEP020 eye tracking)
    DIR/sub-<ID>/ses-<N>/beh/..._recording-eye<K>_physioevents.tsv.gz/.json  (trial and phase onsets)
    DIR/sourcedata/<study>/sub-<ID>/ses-<N>/: session.json, protocol.yaml, the finalised parquet files

Times: every onset, ``StartTime`` and ``timestamp`` is on the session clock of that run (seconds
since the run's clock started), so the events, physio and physioevents of a run share one timeline.
Every session is verified first (:func:`psyop.finalised.verify_session`): a damaged or edited session
is refused, never exported. ``tests/export/test_bids_export.py`` runs the official validator
(``bids-validator-deno``) on an export of simulated sessions.
"""

from __future__ import annotations

import gzip
import io
import json
import re
import shutil
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np
import pandas as pd

from psyop import __version__
from psyop import datacontract as dc
from psyop.atomic import write_atomic
from psyop.errors import UserError
from psyop.export.gaze import (FRAME_LOG, RunDisplay, display_from_metadata, gaze_on_image_px, image_geometry,
                               run_display, session_gaze)
from psyop.finalised import verify_session
from psyop.optics.angles import fick_direction
from psyop.optics.display import DisplayProfile
from psyop.quality.validation import final_attempts, read_validations
from psyop.records import JsonMapping, JsonObject
from psyop.session.log.record import SessionRecord, read_record_file
from psyop.session.timing import timing_column_description

#: The BIDS version the export follows (the schema bundled with bids-validator-deno 3.0.2).
BIDS_VERSION = "1.11.1"
#: Trial-table columns written as events columns besides onset/duration/trial_type (when present).
EVENT_COLUMNS: tuple[str, ...] = ("trial", "block", "response", "correct", "response_time", "practice")
#: Per-trial columns that are bookkeeping, not events columns (the full table is in sourcedata/).
_NOT_EVENT_COLUMNS = {"study", "participant", "session", dc.TRIAL_START_S, dc.TRIAL_END_S, "condition",
                      "response_time_s", "run", "trial_seed", "n_frames", "drift_correction_deg"}
_NOT_EVENT_PREFIXES = ("hand_sample_",)


@dataclass(frozen=True)
class ExportedSession:
    study: str
    participant: str
    session: int
    runs: int
    gaze_source: str
    eyes: tuple[str, ...]
    n_gaze_samples: int


@dataclass(frozen=True)
class BidsExport:
    """What :func:`export_bids` wrote."""

    root: Path
    sessions: tuple[ExportedSession, ...]


def task_label(study: str) -> str:
    """A BIDS label (letters and digits) for a study name.

    Examples
    --------
    >>> task_label("detection_quest-plus")
    'detectionquestplus'
    """
    return re.sub(r"[^A-Za-z0-9]", "", study)


def export_bids(data_root: Path, out: Path) -> BidsExport:
    """Write every session under ``data_root`` as a BIDS dataset in ``out`` (new or empty).

    Examples
    --------
    >>> export_bids(Path("no-such-data-root"), Path("out"))
    Traceback (most recent call last):
    ...
    psyop.errors.UserError: no-such-data-root: no finalised sessions (<study>/sub-<ID>/ses-<N>/trials.parquet) to export
    """
    data_root, out = Path(data_root), Path(out)
    trials_files = sorted(data_root.glob(f"*/sub-*/ses-*/{dc.TRIALS_FILE}"))
    if not trials_files:
        raise UserError(f"no finalised sessions (<study>/sub-<ID>/ses-<N>/{dc.TRIALS_FILE}) to export", str(data_root))
    for path in trials_files:  # refuse before writing anything
        verify_session(path.parent)
    _check_task_labels(sorted({p.parents[2].name for p in trials_files}), data_root)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise UserError("the export directory exists and is not empty; give a new directory", str(out))
    out.mkdir(parents=True, exist_ok=True)
    exported = [_export_session(path.parent, out) for path in trials_files]
    _write_participants(out, exported, data_root)
    _write_phenotype(out, [path.parent for path in trials_files])
    _write_json(out / "dataset_description.json", _description(exported))
    write_atomic(out / "README.md", _readme(exported))
    return BidsExport(out, tuple(exported))


def _check_task_labels(studies: Sequence[str], data_root: Path) -> None:
    seen: dict[str, str] = {}
    for study in studies:
        label = task_label(study)
        if not label or label in seen:
            raise UserError(f"studies {seen.get(label)!r} and {study!r} map to one BIDS task label {label!r}; "
                            "rename one study folder", str(data_root))
        seen[label] = study


def _export_session(directory: Path, out: Path) -> ExportedSession:
    record = read_record_file(directory / dc.SESSION_METADATA_FILE) or SessionRecord()
    study = directory.parents[1].name
    participant = directory.parent.name.removeprefix("sub-")
    session = int(directory.name.removeprefix("ses-"))
    trials = pd.read_parquet(directory / dc.TRIALS_FILE)
    where = str(directory / dc.SESSION_METADATA_FILE)
    display = display_from_metadata(record.raw, where)
    if record.rig is None:
        raise UserError("session.json records no eye rig (\"rig\": eyes and ipd_m): cannot place gaze on each "
                        "eye's image", where)
    eyes = tuple(e for e in ("left", "right") if e in record.rig.eyes)
    ipd_m = record.rig.ipd_m
    gaze = session_gaze(directory)
    measures = _session_measures(directory)
    validations = read_validations(directory)  # the protocol's gaze validations (None: it has none)
    beh = out / f"sub-{participant}" / f"ses-{session}" / "beh"
    beh.mkdir(parents=True, exist_ok=True)
    runs = sorted(int(r) for r in trials["run"].dropna().unique()) if "run" in trials else [0]
    phases = record.phases
    for run in runs:
        run_trials = trials[trials["run"] == run] if "run" in trials else trials
        run_trials = run_trials.sort_values(dc.TRIAL_START_S, kind="stable")
        stem = f"sub-{participant}_ses-{session}_task-{task_label(study)}_run-{run + 1}"
        used = run_display(record.raw, run, display, where)  # the display this run really used, where it measured it
        _write_events(beh / f"{stem}_events", run_trials, used, eyes, record, study)
        samples = _run_samples(gaze.samples, run_trials, gaze.source)
        for index, eye in enumerate(eyes):
            recording = f"{stem}_recording-eye{index + 1}"
            calibration = validation_fields(validations, run, used.eyes[eye], eye, ipd_m) if validations is not None \
                else calibration_fields(measures, run_trials, phases)
            _write_physio(beh / f"{recording}_physio", samples, used, eye, ipd_m, gaze.source, gaze.file, record,
                          calibration)
            _write_physioevents(beh / f"{recording}_physioevents", run_trials, phases, study)
    _copy_sourcedata(directory, out / "sourcedata" / study / f"sub-{participant}" / f"ses-{session}", record)
    return ExportedSession(study, participant, session, len(runs), gaze.source, eyes, len(gaze.samples))


def _run_samples(samples: pd.DataFrame, run_trials: pd.DataFrame, source: str) -> pd.DataFrame:
    """The gaze samples of one run: the frame log's by trial; a raw stream's by the run's time span."""
    if source == FRAME_LOG:
        return samples[samples["trial"].isin(run_trials["trial"])].reset_index(drop=True)
    if "run" in samples and "run" in run_trials:  # a real clock restarts with each run: times alone overlap
        return samples[samples["run"].isin(run_trials["run"].unique())].reset_index(drop=True)
    start, end = float(run_trials[dc.TRIAL_START_S].min()), float(run_trials[dc.TRIAL_END_S].max())
    t = samples[dc.GAZE_SAMPLE_T_S]
    return samples[(t >= start) & (t <= end)].reset_index(drop=True)


# ---- events ------------------------------------------------------------------------------------------------
def _stimulus_presentation(display: DisplayProfile, eye: str) -> JsonObject:
    geometry = image_geometry(display, eye)
    return {
        "ScreenDistance": geometry.distance_m,
        "ScreenOrigin": ["top", "left"],
        "ScreenResolution": [geometry.width_px, geometry.height_px],
        "ScreenSize": [round(geometry.width_m, 9), round(geometry.height_m, 9)],
        "ScreenRefreshRate": float(display.refresh_hz),
        "SoftwareName": "psyop",
        "SoftwareVersion": __version__,
    }


def _screen_note(display: DisplayProfile) -> str:
    if np.isfinite(display.d_m):
        return (f"Each eye sees the head-mounted display {display.name!r}: a virtual image {display.d_m} m in front "
                "of the eye's centre of rotation; ScreenDistance and ScreenSize are that image's.")
    return (f"Each eye sees the head-mounted display {display.name!r}, whose virtual image is at optical infinity: "
            "ScreenDistance and ScreenSize describe the equivalent flat screen 1 m from the eye's centre of rotation "
            "that subtends the same angles (the same visual angle for every pixel), not a physical screen.")


def _write_events(stem: Path, trials: pd.DataFrame, used: RunDisplay, eyes: Sequence[str], record: SessionRecord,
                  study: str) -> None:
    events = pd.DataFrame({
        "onset": trials[dc.TRIAL_START_S].astype(float).to_numpy(),
        "duration": (trials[dc.TRIAL_END_S].astype(float) - trials[dc.TRIAL_START_S].astype(float)).to_numpy(),
        "trial_type": trials["condition"].astype(str).to_numpy() if "condition" in trials else "trial",
    })
    if "trial" in trials:
        events["trial"] = trials["trial"].astype(int).to_numpy()
    if "block" in trials:
        events["block"] = trials["block"].astype(int).to_numpy()
    events["response"] = trials[dc.RESPONSE].astype(str).to_numpy() if dc.RESPONSE in trials else "n/a"
    events["correct"] = [_flag(v) for v in trials[dc.CORRECT]] if dc.CORRECT in trials else "n/a"
    if "response_time_s" in trials:
        events["response_time"] = trials["response_time_s"].astype(float).to_numpy()
    extra = [c for c in trials.columns if c not in _NOT_EVENT_COLUMNS and c not in events and c != dc.CORRECT
             and not c.startswith(_NOT_EVENT_PREFIXES) and trials[c].notna().any() and not _is_list_column(trials[c])]
    for column in extra:
        values = trials[column]
        flags = values.dtype == bool or values.dropna().map(lambda v: isinstance(v, (bool, np.bool_))).all()
        events[column] = [_flag(v) for v in values] if flags else values.to_numpy()
    _write_tsv(stem.with_suffix(".tsv"), events)
    described = {
        "onset": {"Description": "trial start on the session clock of this run", "Units": "s"},
        "duration": {"Description": "trial start to the end of its response phase", "Units": "s"},
        "trial_type": {"LongName": "condition", "Description": "psyop's condition label of the trial (factor=value|...)"},
        "trial": {"Description": "psyop trial number (0-based, schedule order)"},
        "block": {"Description": "block number (0-based)"},
        "response": {"Description": f"the participant's response; {dc.TIMEOUT_RESPONSE!r}: the response phase timed out"},
        "correct": {"Description": "correctness of the response (1 correct, 0 wrong, n/a: no correct answer or timed out)",
                    "Levels": {"1": "correct", "0": "wrong"}},
        "response_time": {"Description": "response time from the start of the response phase", "Units": "s"},
        dc.RESPONSE_VALUE: {"Description": "the response as a number where it is one (the interval chosen, 1 or 2; a "
                                           "reach in metres); n/a otherwise (left/right, a mode name, a timeout)",
                            **({"Units": "m"} if record.response_kind == "reach" else {})},
        dc.OUTCOME: {"Description": "what happened to the trial's response phase",
                     "Levels": {"answered": "a response was given",
                                dc.TIMEOUT_RESPONSE: "the response phase timed out (protocol timeout_s)"}},
    }
    sidecar: JsonObject = {
        "TaskName": study,
        "TaskDescription": (record.response.question if record.response else None) or study,
        "StimulusPresentation": _stimulus_presentation(used.eyes[eyes[0]], eyes[0]),
        "StimulusPresentationNote": f"{_screen_note(used.eyes[eyes[0]])} {used.note}",
    }
    phase_names = [str(p.get("name")) for p in record.phases]
    for column in events.columns:
        sidecar[column] = described.get(column) or timing_column_description(column, phase_names) or {
            "Description": f"schedule column {column!r} of psyop's trials.parquet (see sourcedata/)"}
    _write_json(stem.with_suffix(".json"), sidecar)


def _is_list_column(values: pd.Series) -> bool:
    sample = values.dropna()
    return bool(len(sample)) and isinstance(sample.iloc[0], (list, tuple, np.ndarray))


def _flag(value: object) -> int | str:
    if value is None or (isinstance(value, float) and np.isnan(value)) or value is pd.NA:
        return "n/a"
    return int(bool(value))


# ---- physio ----------------------------------------------------------------------------------------------
def _session_measures(directory: Path) -> pd.DataFrame:
    """psyop.quality's per-trial measures of the session (empty when its recorded protocol no longer validates
    here, e.g. a mesh it named has moved: the calibration fields are then left out, never guessed)."""
    from psyop.quality.session import measure_session

    try:
        return measure_session(directory)[0]
    except UserError:
        return pd.DataFrame()


def calibration_fields(measures: pd.DataFrame, run_trials: pd.DataFrame,
                       phases: Sequence[JsonMapping]) -> JsonObject:
    """BIDS eye-tracking calibration fields of one run (names, types and units as bids-validator-deno 3.0.2's
    schema: AverageCalibrationError and MaximalCalibrationError numbers in degrees, CalibrationCount an
    integer). psyop's calibration check is the per-trial single-point drift recalibration on the cross: the
    errors are psyop.quality's ``accuracy_fixation_mean_deg`` (mean over the run's trials) and
    ``accuracy_fixation_max_deg`` (largest), before the correction; the count is the run's recalibrations.
    A field with nothing measured (no cross phase, no valid sample) is left out."""
    n_cross = sum(1 for p in phases if p.get("name") == "recalibration")
    fields: JsonObject = {}
    if n_cross:
        fields["CalibrationType"] = "one-point drift recalibration on the fixation cross before every trial (psyop)"
        fields["CalibrationCount"] = int(n_cross * len(run_trials))
    if measures.empty or "trial" not in run_trials:
        return fields
    rows = measures[measures["trial"].isin(run_trials["trial"].astype(int))]
    mean, largest = rows["accuracy_fixation_mean_deg"].mean(), rows["accuracy_fixation_max_deg"].max()
    if np.isfinite(mean) and np.isfinite(largest):
        fields["AverageCalibrationError"], fields["MaximalCalibrationError"] = float(mean), float(largest)
    return fields


def validation_fields(validations: pd.DataFrame, run: int, display: DisplayProfile, eye: str,
                      ipd_m: float) -> JsonObject:
    """BIDS eye-tracking calibration fields of one run from its gaze validations (psyop.session.validation;
    names, types and units as bids-validator-deno 3.0.2's schema): CalibrationCount the run's validation
    attempts; AverageCalibrationError (degrees) the mean over the run's validations (each one's last attempt)
    of the mean error over the points; MaximalCalibrationError (degrees) the largest sample error of those
    attempts; CalibrationType ``HV<n>`` (n points); CalibrationPosition the points on ``eye``'s image in
    pixels (CalibrationUnit ``pixel``). The run without a validation has the count 0 and no error fields."""
    own = validations[validations["run"] == run]
    points = own[own["point"] >= 0].drop_duplicates("point").sort_values("point")
    fields: JsonObject = {"CalibrationCount": int((own["point"] == -1).sum())}
    if points.empty:
        return fields
    target_m = points["distance_m"].to_numpy()[:, None] * fick_direction(points["target_az_deg"].to_numpy(),
                                                                          points["target_el_deg"].to_numpy())
    px = gaze_on_image_px(target_m, display, eye, ipd_m)
    fields["CalibrationType"] = f"HV{len(points)}"
    if np.isfinite(px).all():
        fields["CalibrationPosition"] = [[float(x), float(y)] for x, y in px]
        fields["CalibrationUnit"] = "pixel"
    done = final_attempts(own)
    mean, largest = done["mean_error_deg"].mean(), done["max_error_deg"].max()
    if np.isfinite(mean) and np.isfinite(largest):
        fields["AverageCalibrationError"], fields["MaximalCalibrationError"] = float(mean), float(largest)
    return fields


def _write_physio(stem: Path, samples: pd.DataFrame, used: RunDisplay, eye: str, ipd_m: float, source: str,
                  source_file: str, record: SessionRecord, calibration: Mapping[str, object]) -> None:
    display = used.eyes[eye]
    fixation = samples[list(dc.FIXATION_COLUMNS)].to_numpy(dtype=np.float64)
    valid = samples[dc.GAZE_VALID].fillna(False).astype(bool).to_numpy()
    px = gaze_on_image_px(fixation, display, eye, ipd_m)
    px[~valid] = np.nan
    table = pd.DataFrame({"timestamp": samples[dc.GAZE_SAMPLE_T_S].astype(float).to_numpy(),
                          "x_coordinate": px[:, 0], "y_coordinate": px[:, 1]})
    columns: JsonObject = {
        "timestamp": {"Description": "time of the tracker sample on the session clock of this run", "Units": "s"},
        "x_coordinate": {"Description": f"where the {eye} eye's line of sight (from its centre of rotation through "
                         "the tracked fixation point) meets its display image, from the left edge", "Units": "pixel"},
        "y_coordinate": {"Description": f"as x_coordinate, from the top edge of the {eye} eye's image",
                         "Units": "pixel"},
    }
    pupil = f"pupil_diameter_{eye}_mm"
    if pupil in samples:
        table["pupil_size"] = samples[pupil].astype(float).to_numpy()
        columns["pupil_size"] = {"Description": f"pupil diameter of the {eye} eye as the tracker reports it",
                                 "Units": "mm"}
    table["confidence"] = samples[dc.GAZE_CONFIDENCE].astype(float).to_numpy()
    table["valid"] = valid.astype(int)
    columns["confidence"] = {"Description": "the tracker's confidence in the sample (0..1; n/a: not reported)"}
    columns["valid"] = {"Description": "1: a usable sample; 0: blink, dropout or low confidence (coordinates n/a)"}
    _write_tsv_gz(stem.with_suffix(".tsv.gz"), table)
    sampling, rate = _sampling(source, display, table)
    sidecar = {
        "TaskName": record.study or "",
        "PhysioType": "eyetrack",
        "SamplingFrequency": rate,
        "StartTime": float(table["timestamp"].iloc[0]) if len(table) else 0.0,
        "Columns": list(table.columns),
        "RecordedEye": eye,
        "SampleCoordinateSystem": "gaze-on-screen",
        "SampleCoordinateUnits": "pixel",
        "EnvironmentCoordinates": "top-left",
        "Manufacturer": _tracker_manufacturer(record.tracker),
        "SoftwareVersions": f"psyop {__version__}",
        "Description": (f"Eye tracking of the {eye} eye from psyop's {source} ({source_file}). "
                        f"{'Simulated tracker: ' if record.simulated else ''}the tracker reports one "
                        "fixation point in head space for both eyes; this file is that point seen by the "
                        f"{eye} eye, on its image. {sampling}"),
        "GazeSource": source,
        "StimulusPresentation": _stimulus_presentation(display, eye),
        "StimulusPresentationNote": f"{_screen_note(display)} {used.note}",
        **calibration, **columns,
    }
    _write_json(stem.with_suffix(".json"), sidecar)


def _sampling(source: str, display: DisplayProfile, table: pd.DataFrame) -> tuple[str, float]:
    """The physio sidecar's account of its samples, and its SamplingFrequency."""
    if source == FRAME_LOG:
        return ("Samples are the gaze samples the rendered frames used (psyop's frame log, frames.parquet): at "
                "most one per displayed frame, after psyop's per-trial drift correction, so SamplingFrequency is the "
                "display refresh rate; frames not rendered or checked (simulated sessions render a few per trial) "
                "leave gaps and a sample reused by several frames is written once. The timestamp column gives each "
                "sample's time. No pupil size: the frame log does not record it."), float(display.refresh_hz)
    rate = _median_rate_hz(table["timestamp"].to_numpy())
    return ("Samples are every sample of the tracker's raw gaze stream (gaze.parquet), as the tracker delivered them: "
            f"before psyop's per-trial drift correction. SamplingFrequency ({rate:.6g} Hz) is 1 / the median interval "
            "between samples: psyop does not record the tracker's nominal rate."), rate


def _median_rate_hz(timestamps_s: np.ndarray) -> float:
    """1 / median positive interval between samples (a run with fewer than two samples: 0)."""
    steps = np.diff(np.sort(timestamps_s[np.isfinite(timestamps_s)]))
    steps = steps[steps > 0]
    return float(1.0 / np.median(steps)) if len(steps) else 0.0


def _tracker_manufacturer(tracker: object) -> str:
    """The tracker kind of psyop's ``--tracker`` (never its host or file argument)."""
    kind = str(tracker or "").split(":", 1)[0]
    return {"sim": "none (psyop simulated tracker)", "pupil": "Pupil Labs", "replay": "replayed gaze log",
            "serial": "serial-line tracker", "lsl": "Lab Streaming Layer stream"}.get(kind, "unknown")


def _write_physioevents(stem: Path, trials: pd.DataFrame, phases: Sequence[JsonMapping], study: str) -> None:
    rows: list[tuple[float, float, str, str]] = []
    for trial in trials.itertuples(index=False):
        start, end = float(trial.trial_start_s), float(trial.trial_end_s)
        number = int(trial.trial)
        rows.append((start, end - start, "trial", f"trial {number} {getattr(trial, 'condition', '')}".strip()))
        onset = start
        for phase in phases:
            duration = float(phase.get("duration_s") or 0.0)
            rows.append((onset, duration, f"phase_{phase.get('name')}", f"trial {number} phase {phase.get('name')}"))
            onset += duration
        rows.append((onset, max(0.0, end - onset), "phase_response", f"trial {number} response"))
    table = pd.DataFrame(rows, columns=["onset", "duration", "trial_type", "message"])
    _write_tsv_gz(stem.with_suffix(".tsv.gz"), table)
    _write_json(stem.with_suffix(".json"), {
        "TaskName": study,
        "Columns": list(table.columns),
        "OnsetSource": "timestamp",
        "Description": ("Trial onsets (trial_type 'trial') and phase onsets (phase_<name>) on the session clock, the "
                        "timeline of the physio file's timestamp column. A phase starts when the previous one ends: "
                        "the session loop runs each phase of session.json's \"phases\" for its duration_s, then the "
                        "response phase until the response."),
        "onset": {"Description": "event onset on the session clock", "Units": "s"},
        "duration": {"Description": "event duration", "Units": "s"},
        "trial_type": {"Description": "'trial' or 'phase_<phase name>'"},
        "message": {"Description": "trial number, condition or phase"},
    })


# ---- dataset files -----------------------------------------------------------------------------------------
def _copy_sourcedata(directory: Path, target: Path, record: SessionRecord) -> None:
    target.mkdir(parents=True, exist_ok=True)
    shutil.copy2(directory / dc.SESSION_METADATA_FILE, target / dc.SESSION_METADATA_FILE)
    for name in record.finalised_files:
        shutil.copy2(directory / name, target / name)
    if record.protocol_text:
        write_atomic(target / "protocol.yaml", record.protocol_text)


def _write_participants(out: Path, exported: Sequence[ExportedSession], data_root: Path) -> None:
    by_participant: dict[str, list[ExportedSession]] = {}
    for s in exported:
        by_participant.setdefault(s.participant, []).append(s)
    simulated = {}
    for participant, sessions in by_participant.items():
        flags = {bool((read_record_file(data_root / s.study / f"sub-{s.participant}" / f"ses-{s.session}"
                                        / dc.SESSION_METADATA_FILE) or SessionRecord()).simulated) for s in sessions}
        simulated[participant] = "mixed" if len(flags) > 1 else ("true" if flags == {True} else "false")
    table = pd.DataFrame({
        "participant_id": [f"sub-{p}" for p in sorted(by_participant)],
        "simulated": [simulated[p] for p in sorted(by_participant)],
        "studies": [",".join(sorted({s.study for s in by_participant[p]})) for p in sorted(by_participant)],
    })
    _write_tsv(out / "participants.tsv", table)
    _write_json(out / "participants.json", {
        "participant_id": {"Description": "psyop participant ID"},
        "simulated": {"Description": "whether the participant's sessions were simulated (session.json "
                      "\"simulated\"); mixed: some were", "Levels": {"true": "simulated", "false": "real",
                                                                     "mixed": "both"}},
        "studies": {"Description": "psyop studies (BIDS tasks) the participant took part in"},
    })


def _write_phenotype(out: Path, sessions: Sequence[Path]) -> None:
    """The sessions' questionnaire answers (questionnaires.parquet, the protocol's ``session: questionnaires``) as BIDS
    phenotype files: one measurement tool per questionnaire and administration, ``phenotype/<name>_<when>[_<k>].tsv``
    (``k`` counts repeated administrations of one ``when`` in a session, e.g. between blocks), one row per participant,
    session and task, one column per item (the answer, 0 .. points - 1; n/a when none), and its sidecar with the
    items' texts and the scale's labels."""
    frames = [pd.read_parquet(d / dc.QUESTIONNAIRES_FILE) for d in sessions if (d / dc.QUESTIONNAIRES_FILE).exists()]
    answers = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()
    if answers.empty:
        return
    answers["occurrence"] = answers["run"].astype(int) * 1_000_000 + answers["administration"].astype(int)
    answers["k"] = answers.groupby(["study", "participant", "session", "questionnaire", "when"])["occurrence"].rank(
        method="dense").astype(int)
    folder = out / "phenotype"
    folder.mkdir(exist_ok=True)
    for (name, when, k), table in answers.groupby(["questionnaire", "when", "k"], sort=True):
        repeated = int(answers.loc[(answers["questionnaire"] == name) & (answers["when"] == when), "k"].max()) > 1
        tool = f"{name}_{when}" + (f"_{k}" if repeated else "")
        items = table.drop_duplicates("item").sort_values("item")
        width = max(2, len(str(int(items["item"].max()) + 1)))
        columns = {int(i): f"item{int(i) + 1:0{width}d}" for i in items["item"]}
        wide = table.pivot_table(index=["participant", "session", "study"], columns="item", values="answer",
                                 aggfunc="first").rename(columns=columns).reset_index()
        rows = pd.DataFrame({"participant_id": "sub-" + wide["participant"].astype(str),
                             "session_id": "ses-" + wide["session"].astype(int).astype(str),
                             "task": [task_label(str(study)) for study in wide["study"]]})
        for column in columns.values():
            rows[column] = [("n/a" if pd.isna(v) else int(v)) for v in wide.get(column, pd.Series(dtype=float))]
        _write_tsv(folder / f"{tool}.tsv", rows)
        sidecar: JsonObject = {
            "MeasurementToolMetadata": {"Description": f"psyop questionnaire '{name}' given at '{when}'"
                                        + (f" (administration {k})" if repeated else "")
                                        + (" (the Simulator Sickness Questionnaire, Kennedy et al. 1993)"
                                           if name == "ssq" else "")},
            "participant_id": {"Description": "psyop participant ID"},
            "session_id": {"Description": "the psyop session"},
            "task": {"Description": "the psyop study (BIDS task) whose session gave the questionnaire"}}
        for row in items.to_dict("records"):
            labels = table[table["item"] == row["item"]].dropna(subset=["answer"]).drop_duplicates("answer")
            sidecar[columns[int(row["item"])]] = {
                "Description": f"{row['item_text']} (answer 0 .. {int(row['scale_points']) - 1}; the levels "
                               "listed are those given)",
                "Levels": {str(int(a)): str(label) for a, label in
                           sorted(zip(labels["answer"], labels["answer_label"]))}}
        _write_json(folder / f"{tool}.json", sidecar)


def _description(exported: Sequence[ExportedSession]) -> JsonObject:
    studies = sorted({s.study for s in exported})
    return {
        "Name": f"psyop sessions: {', '.join(studies)}",
        "BIDSVersion": BIDS_VERSION,
        "DatasetType": "raw",
        "GeneratedBy": [{"Name": "psyop", "Version": __version__,
                         "Description": "psyop export --bids (psyop.export.bids)"}],
    }


def _readme(exported: Sequence[ExportedSession]) -> str:
    lines = ["# psyop sessions in BIDS", "",
             "Exported by `psyop export --bids` from psyop's data root. Per session and psyop run (BIDS `run`):",
             "", "- `beh/*_events.tsv`: one row per trial (onset, duration, trial_type = condition, response, "
             "correct, and the schedule's factor columns).",
             "- `beh/*_recording-eye<K>_physio.tsv.gz`: eye tracking (BIDS eye-tracking, `PhysioType` eyetrack), "
             "gaze on each eye's display image in pixels; the sidecar says which eye, where the samples came from "
             "(raw gaze stream or frame log) and the image geometry.",
             "- `beh/*_physioevents.tsv.gz`: trial and phase onsets on the physio timeline.",
             "- `sourcedata/<study>/sub-<ID>/ses-<N>/`: psyop's session.json (with the SHA-256 of each finalised "
             "file), the protocol, and the finalised parquet files.", "",
             "Times are seconds on the session clock of each run.", "", "## Sessions", "",
             "| study | participant | session | runs | gaze source | eyes | gaze samples |", "|---|---|---|---|---|---|---|"]
    for s in exported:
        lines.append(f"| {s.study} | {s.participant} | {s.session} | {s.runs} | {s.gaze_source} | "
                     f"{', '.join(s.eyes)} | {s.n_gaze_samples} |")
    return "\n".join(lines) + "\n"


def _tsv_text(table: pd.DataFrame, header: bool) -> str:
    buffer = io.StringIO()
    table.to_csv(buffer, sep="\t", index=False, header=header, na_rep="n/a", lineterminator="\n",
                 float_format="%.6f")
    return buffer.getvalue()


def _write_tsv(path: Path, table: pd.DataFrame) -> None:
    write_atomic(path, _tsv_text(table, header=True))


def _write_tsv_gz(path: Path, table: pd.DataFrame) -> None:
    """Headerless (BIDS continuous recordings), gzip with no name or time in its header (reproducible)."""
    def write(raw: BinaryIO) -> None:
        with gzip.GzipFile(filename="", mode="wb", fileobj=raw, mtime=0) as handle:
            handle.write(_tsv_text(table, header=False).encode())

    write_atomic(path, write)


def _write_json(path: Path, content: JsonMapping) -> None:
    write_atomic(path, json.dumps(content, indent=2, default=_json_default) + "\n")


def _json_default(value: object) -> int | float | bool:
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    if isinstance(value, np.bool_):
        return bool(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
